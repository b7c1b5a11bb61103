"""The build step that stamps a wheel with lawn's commit (the project is configured in pyproject.toml).

A wheel or sdist built from a git checkout of lawn carries ``evaluation/_build_info.json``
(``{"commit", "dirty"}``, :func:`evaluation.provenance.source_stamp`), so that an installed lawn
reports the commit it was built from, not that of whatever repository holds the install. An
editable install reads its checkout's git at run time and gets no stamp; a wheel built from an
sdist keeps the sdist's stamp.
"""

import importlib.util
import json
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py
from setuptools.command.sdist import sdist

ROOT = Path(__file__).resolve().parent
STAMP = Path("evaluation") / "_build_info.json"


def _stamp() -> dict | None:
    spec = importlib.util.spec_from_file_location("_lawn_provenance", ROOT / "evaluation" / "provenance.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.source_stamp(ROOT)


def _write(target: Path) -> None:
    stamp = _stamp()
    if stamp is not None:
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text(json.dumps(stamp) + "\n")
    elif (ROOT / STAMP).exists():  # building from an sdist: its stamp
        shutil.copyfile(ROOT / STAMP, target)
    else:  # no commit known: no stamp (not one left in build/ by an earlier build)
        target.unlink(missing_ok=True)


class BuildPy(build_py):
    def run(self):
        super().run()
        if not getattr(self, "editable_mode", False):
            _write(Path(self.build_lib) / STAMP)


class Sdist(sdist):
    def make_release_tree(self, base_dir, files):
        super().make_release_tree(base_dir, files)
        _write(Path(base_dir) / STAMP)


setup(cmdclass={"build_py": BuildPy, "sdist": Sdist})
