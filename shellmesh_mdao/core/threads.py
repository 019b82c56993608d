"""A call in a thread of its own, for work that releases the GIL beside the caller's work."""
from __future__ import annotations

import threading

__all__ = ["Background"]

class Background:
    """``fn(*args)`` in a thread of its own from now on; :meth:`result` waits for its value (or
    raises its exception). For work that releases the GIL (a KD-tree query, a compiled
    ``nogil`` loop) beside work in the caller's thread; the value is the same as a call in the
    caller's. One short-lived thread per call rather than a shared ``concurrent.futures``
    pool: a pool's idle worker does not survive a ``fork`` (a study's multiprocessing pool),
    and the child's ``submit`` would wait for it forever. (Used by the smoothing's trust
    radius and :meth:`TriangleBVH.closest`.)"""

    def __init__(self, fn, *args):
        self._out: list = []

        def run():
            try:
                self._out.append((True, fn(*args)))
            except BaseException as exc:          # handed to the caller by result()
                self._out.append((False, exc))

        self._thread = threading.Thread(target=run, daemon=True)
        self._thread.start()

    def result(self):
        self._thread.join()
        ok, value = self._out[0]
        if not ok:
            raise value
        return value

