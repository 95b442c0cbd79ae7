# The Rust extension module (python/src, built by maturin): typed as Any until it has stubs of its
# own, so that mypy (mypy.ini) checks the Python modules that call it.
from typing import Any

def __getattr__(name: str) -> Any: ...
