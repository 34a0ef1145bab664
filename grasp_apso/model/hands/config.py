"""The override config of a hand: a small YAML file (or dict) that replaces what the
derivation would find (docs/hands.md has the example).

Keys (all optional)::

    root_link: palm                 # the palm; joints above it are held
    hold: {WRJ1: 0.0}               # values of held joints (default 0 clipped into range)
    fingers: {index: ffdistal, thumb: thdistal}   # finger name -> tip link (replaces the list)
    thumb: thumb                    # which finger opposes the others
    closing: {FFJ3: 0, FFJ2: 1}     # per joint: +1 / -1 closing sense, 0 pre-shape
    palm_normal: [0, -1, 0]         # root frame
    pads: {index: {link: ffdistal, center: [0, -0.007, 0.02], radius: 0.008}}
    sphere_tolerance: 0.002         # m, how far spheres may stray outside the geometry
    max_spheres: 24                 # per link

Every value is checked; a bad one raises HandDescriptionError naming ``hand_config.<key>``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from ...errors import HandDescriptionError

__all__ = ["HandConfig", "read_config"]

_KEYS = ("root_link", "hold", "fingers", "thumb", "closing", "palm_normal", "pads", "sphere_tolerance",
         "max_spheres")


def _bad(key: str, why: str) -> HandDescriptionError:
    return HandDescriptionError(f"hand_config.{key}: {why}", field=f"hand_config.{key}")


def _number(value: Any, key: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(float(value)):
        raise _bad(key, f"expected a finite number, got {value!r}")
    return float(value)


def _vector(value: Any, key: str) -> tuple[float, float, float]:
    if not isinstance(value, (list, tuple)) or len(value) != 3:
        raise _bad(key, "expected 3 numbers")
    return tuple(_number(v, key) for v in value)


class HandConfig(dict):
    """A checked override config (a dict; ``canonical`` is its text for the cache key)."""

    @property
    def canonical(self) -> str:
        return json.dumps(self, sort_keys=True, default=str)


def read_config(config: str | Path | dict | None) -> HandConfig:
    """Parse and check an override config (a YAML file path or a dict; None = empty)."""
    if config is None or config == "":
        return HandConfig()
    if isinstance(config, (str, Path)):
        try:
            data = yaml.safe_load(Path(config).read_text(encoding="utf-8"))
        except OSError as exc:
            raise HandDescriptionError(f"hand_config: cannot read {config}: {exc.strerror}", field="hand_config") from None
        except yaml.YAMLError:
            raise HandDescriptionError(f"hand_config: {config} is not valid YAML", field="hand_config") from None
        data = {} if data is None else data
    else:
        data = config
    if not isinstance(data, dict):
        raise HandDescriptionError("hand_config: expected a mapping", field="hand_config")
    out = HandConfig()
    for key, value in data.items():
        if key not in _KEYS:
            raise _bad(str(key), f"unknown key (expected one of {', '.join(_KEYS)})")
        if key in ("root_link", "thumb"):
            if not isinstance(value, str) or not value:
                raise _bad(key, "expected a name")
            out[key] = value
        elif key in ("hold", "closing", "fingers", "pads"):
            if not isinstance(value, dict):
                raise _bad(key, "expected a mapping")
            out[key] = {str(k): _entry(key, str(k), v) for k, v in value.items()}
        elif key == "palm_normal":
            v = np.asarray(_vector(value, key))
            if np.linalg.norm(v) < 1e-9:
                raise _bad(key, "is zero")
            out[key] = tuple(v / np.linalg.norm(v))
        elif key == "sphere_tolerance":
            t = _number(value, key)
            if not 0.0002 <= t <= 0.01:
                raise _bad(key, f"{t} outside [0.0002, 0.01] m")
            out[key] = t
        elif key == "max_spheres":
            if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 256:
                raise _bad(key, "expected an integer in [1, 256]")
            out[key] = value
    return out


def _entry(key: str, name: str, value: Any) -> Any:
    where = f"{key}.{name}"
    if key == "hold":
        return _number(value, where)
    if key == "closing":
        if value not in (-1, 0, 1) or isinstance(value, bool):
            raise _bad(where, f"expected -1, 0 or 1, got {value!r}")
        return int(value)
    if key == "fingers":
        if not isinstance(value, str) or not value:
            raise _bad(where, "expected a tip link name")
        return value
    if not isinstance(value, dict) or set(value) != {"link", "center", "radius"}:
        raise _bad(where, "expected {link, center, radius}")
    radius = _number(value["radius"], where + ".radius")
    if not 0.0 < radius <= 0.1:
        raise _bad(where + ".radius", f"{radius} outside (0, 0.1] m")
    return {"link": str(value["link"]), "center": _vector(value["center"], where + ".center"), "radius": radius}
