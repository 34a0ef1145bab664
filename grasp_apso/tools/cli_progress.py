"""Progress and interruption of ``grasp_apso_plan``: a progress bar (or plain lines) on
stderr per run, and Ctrl-C handling (first: stop after the current iteration; second: abort)."""

from __future__ import annotations

import math
import signal
import sys
import threading

__all__ = ["Progress", "Interrupt"]


def _num(x: float) -> str:
    return f"{x:.3f}" if math.isfinite(x) else "-"


class Progress:
    """Progress of one run on ``stream``: tqdm on a terminal, else a line every 10 iterations."""

    def __init__(self, label: str, total: int, stream, enabled: bool):
        self.label, self.total, self.stream, self.enabled = label, total, stream, enabled
        self.bar = None
        if enabled and hasattr(stream, "isatty") and stream.isatty():
            try:
                from tqdm import tqdm
            except ImportError:  # pragma: no cover - tqdm is a declared dependency
                tqdm = None
            if tqdm is not None:
                self.bar = tqdm(total=total, desc=label, unit="it", file=stream, leave=False,
                                dynamic_ncols=True)

    def __call__(self, stats) -> None:
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.set_postfix_str(
                f"best {stats.best_fitness:.3f}, mean {_num(stats.mean_fitness)}, "
                f"active {stats.active_particles}, contacts {stats.best_contacts}", refresh=False)
            self.bar.update(1)
        elif stats.iteration % 10 == 0 or stats.iteration in (1, stats.iterations):
            print(f"  {self.label} iteration {stats.iteration:>3}/{stats.iterations}: "
                  f"best fitness {stats.best_fitness:.3f}, mean of active {_num(stats.mean_fitness)}, "
                  f"{stats.active_particles} active particles, best has {stats.best_contacts} contacts, "
                  f"{stats.elapsed:.1f} s", file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
            self.bar = None


class Interrupt:
    """Context manager: first Ctrl-C sets ``stop`` (the swarm ends after this iteration);
    a second raises KeyboardInterrupt. Only installed on the main thread."""

    def __init__(self, prog: str):
        self.prog = prog
        self.stop = False
        self._old = None

    def __enter__(self) -> "Interrupt":
        if threading.current_thread() is threading.main_thread():
            self._old = signal.signal(signal.SIGINT, self._handler)
        return self

    def _handler(self, signum, frame) -> None:
        if self.stop:
            raise KeyboardInterrupt
        self.stop = True
        print(f"\n{self.prog}: interrupted: stopping after this iteration (Ctrl-C again to abort)",
              file=sys.stderr, flush=True)

    def __exit__(self, *exc) -> bool:
        if self._old is not None:
            signal.signal(signal.SIGINT, self._old)
        return False
