"""Service responses the middleware drops are sent again.

Why (issue 19.6, a burst where 1 reply of 30 never arrived although the node logged all
30 requests): rmw_fastrtps sends a service response only after the server's response
writer has matched the client's response reader, and waits for that match only briefly.
A client that calls the moment it has discovered the service, on a loaded machine, can
be answered before that match -- a "busy" reply takes milliseconds -- and then rmw
drops the response ("client will not receive response") while rclpy merely warns
(``RuntimeWarning: failed to send response (timeout)``) from the executor's thread: the
client waits forever. The request history depths play no part (they hold 1000).

The mitigation: :func:`resend_dropped_responses` wraps a service's ``send_response``;
when that warning is raised in the sending thread, the response is sent again every
:data:`RETRY_WAIT` s, at most :data:`RETRIES` times (each try waits for the match again),
and a response still dropped is logged as an error. A client that has left is no such
case: rmw then returns without a warning.
"""

from __future__ import annotations

import threading
import time
import warnings
from typing import Any, Callable

__all__ = ["RETRIES", "RETRY_WAIT", "resend_dropped_responses"]

RETRIES = 20
RETRY_WAIT = 0.05  # s, between tries (rmw's own wait for the match comes on top)
_MESSAGE = "failed to send response"
_state = threading.local()
_installing = threading.Lock()


def _install_hook() -> None:
    """The rclpy warning is shown every time (not once per place) and, while a wrapped
    send watches in this thread, recorded instead of printed (installed again when
    something, e.g. ``warnings.catch_warnings``, put its own hooks back)."""
    with _installing:
        if getattr(warnings.showwarning, "_grasp_apso_hook", False):
            return
        warnings.filterwarnings("always", message=_MESSAGE, category=RuntimeWarning)
        original = warnings.showwarning

        def showwarning(message: Any, category: type, filename: str, lineno: int, file: Any = None,
                        line: Any = None) -> None:
            if getattr(_state, "watching", False) and str(message).startswith(_MESSAGE):
                _state.dropped = str(message)
                return
            original(message, category, filename, lineno, file, line)

        showwarning._grasp_apso_hook = True  # type: ignore[attr-defined]
        warnings.showwarning = showwarning


def resend_dropped_responses(service: Any, log: Callable[[str, str], None]) -> None:
    """Make ``service`` (an ``rclpy.service.Service``) send a dropped response again;
    ``log(level, text)`` is told about every retry that succeeded and every final loss."""
    _install_hook()
    send = service.send_response

    def send_response(response: Any, header: Any) -> None:
        rid = getattr(response, "request_id", "?")
        _install_hook()
        for attempt in range(RETRIES + 1):
            _state.watching, _state.dropped = True, ""
            try:
                send(response, header)
            finally:
                _state.watching = False
            if not _state.dropped:
                if attempt:
                    log("info", f"response sent again after {attempt} dropped tries (request {rid})")
                return
            time.sleep(RETRY_WAIT)
        log("error", f"response dropped by the middleware {RETRIES + 1} times, given up "
                     f"(request {rid}): {_state.dropped}")

    service.send_response = send_response
