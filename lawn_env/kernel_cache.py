"""The compiled kernels' on-disk cache follows every source file they compile from.

numba's cache (``cache=True``) keys a kernel by the stamp of the file that defines it. The slot
kernel in ``slot.py`` compiles ``channel.outage_law``, ``dynamics.saturate`` and the other
equations into itself, so with numba's own stamp an edit of ``channel.py`` would leave the cached
slot kernel computing the old equation while every array method follows the new one. Each
equation lives in one function (the point of the layout) only if editing it reaches every caller,
so the kernels of this package are stamped with the contents of all its source files that hold
compiled code: an edit of any of them recompiles them all (once; about 20 s), and an unchanged
package loads from the cache as before.

:func:`install` wraps numba's cache locators (before any kernel of the package is decorated;
``lawn_env/__init__.py`` calls it first). A package whose kernels compile this one's in (``agents``: the
experts' searches call the link's equations) registers itself with :func:`register`: its kernels are
stamped with this package's stamp and its own. Files elsewhere keep numba's own stamp.
"""

from __future__ import annotations

import functools
import hashlib
from pathlib import Path
from typing import Any

from numba.core import caching

__all__ = ["install", "register", "package_stamp"]

PACKAGE = Path(__file__).resolve().parent
#: The packages whose kernels are stamped (:func:`register`): this one, and those that compile it in.
_PACKAGES: list[Path] = [PACKAGE]


@functools.cache
def package_stamp(package: Path = PACKAGE) -> str:
    """SHA-256 of a package's source files that hold compiled code (their names and contents),
    computed once per process."""
    digest = hashlib.sha256()
    for path in sorted(package.glob("*.py")):
        text = path.read_bytes()
        if b"numba" in text:
            digest.update(path.name.encode() + b"\0" + text + b"\0")
    return digest.hexdigest()


def register(package: Path) -> None:
    """Stamp the kernels of the package in directory ``package`` with this package's stamp and its own
    (before any of its kernels is decorated): its kernels compile this package's functions in."""
    package = Path(package).resolve()
    if package not in _PACKAGES:
        _PACKAGES.append(package)


def _stamped(locator: type) -> type:
    """``locator`` whose stamp, for a file of this package, adds :func:`package_stamp`."""

    # a class built on a class known only at run time: mypy sees its base as Any
    class PackageStamped(locator):  # type: ignore[misc]
        def get_source_stamp(self) -> Any:
            stamp = super().get_source_stamp()
            home = Path(self._py_file).resolve().parent
            if home == PACKAGE:
                return stamp, package_stamp()
            if home in _PACKAGES:
                return stamp, package_stamp(), package_stamp(home)
            return stamp

    PackageStamped.__name__ = PackageStamped.__qualname__ = f"PackageStamped{locator.__name__}"
    return PackageStamped


def install() -> None:
    """Stamp this package's kernels with :func:`package_stamp` (idempotent)."""
    impl = caching.CacheImpl if hasattr(caching, "CacheImpl") else caching._CacheImpl  # numba >= 0.61 / 0.60
    if getattr(impl, "_lawn_package_stamp", False):
        return
    source_backed = caching._SourceFileBackedLocatorMixin  # the locators of files on disk
    impl._locator_classes = [_stamped(c) if issubclass(c, source_backed) else c for c in impl._locator_classes]
    impl._lawn_package_stamp = True
