"""numba kernels compiled once per machine (``cache=True``, next to their module or in numba's
user cache): a run that has to compile one says so in one line on stderr, since compiling takes
seconds where loading the cache takes a fraction of one."""

from __future__ import annotations

import sys

_noted: set[str] = set()


def cache_cold(dispatcher) -> bool:
    """True if numba has no usable on-disk cache of ``dispatcher`` yet (the next call
    compiles); False if it has one, or when numba's cache cannot be inspected."""
    try:
        index = dispatcher._cache._cache_file._load_index()  # {} when missing or stale
    except Exception:  # numba's private layout changed: say nothing rather than fail
        return False
    return not index


def cache_note(what: str, *dispatchers) -> None:
    """Print ``railfmu: compiling the <what> kernel ...`` once per process if any of
    ``dispatchers`` is about to be compiled rather than loaded."""
    if what in _noted:
        return
    _noted.add(what)
    if any(cache_cold(d) for d in dispatchers):
        print(f"railfmu: compiling the {what} kernel with numba (once per machine, then cached)",
              file=sys.stderr, flush=True)
