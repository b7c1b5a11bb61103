"""lawn outside its source tree: the provenance stamp of an installed wheel, numba's cache of a
read-only install (the process pool: tests/test_pool.py)."""

import importlib.util
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _git(cwd, *args):
    return subprocess.run(["git", *args], cwd=cwd, capture_output=True, text=True, check=True).stdout.strip()


def _foreign_repo(path: Path) -> str:
    """A git repository of someone else's, with one commit; returns its commit."""
    path.mkdir(parents=True)
    _git(path, "init", "-q")
    (path / "notes.txt").write_text("not lawn\n")
    _git(path, "add", "notes.txt")
    _git(path, "-c", "user.name=x", "-c", "user.email=x@x", "commit", "-qm", "theirs")
    return _git(path, "rev-parse", "--short=10", "HEAD")


def _load(path: Path):
    spec = importlib.util.spec_from_file_location("provenance_copy", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_provenance_never_stamps_an_enclosing_repository(tmp_path):
    theirs = _foreign_repo(tmp_path / "project")
    site = tmp_path / "project" / ".venv" / "site-packages"
    (site / "evaluation").mkdir(parents=True)
    shutil.copy(ROOT / "evaluation" / "provenance.py", site / "evaluation" / "provenance.py")
    copy = _load(site / "evaluation" / "provenance.py")
    assert copy.source_stamp(site) is None  # the enclosing repository is not lawn's
    assert theirs not in copy.provenance() and copy.provenance().endswith("commit unknown")
    (site / "evaluation" / "_build_info.json").write_text('{"commit": "0123456789", "dirty": false}')
    assert copy.provenance().endswith("commit 0123456789")
    from evaluation.provenance import source_stamp

    assert source_stamp(ROOT)["commit"] == _git(ROOT, "rev-parse", "--short=10", "HEAD")


def test_a_wheel_in_a_foreign_repository_reports_lawns_commit_and_caches_outside_itself(tmp_path):
    """Built from this checkout, installed into a folder of another git repository: the stamp is the
    commit the wheel was built from; numba's cache goes to NUMBA_CACHE_DIR, not into the install."""
    wheels = tmp_path / "wheels"
    subprocess.run([sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "-q", "-w",
                    str(wheels), str(ROOT)], check=True, capture_output=True, timeout=300)
    wheel = next(wheels.glob("lawn-*.whl"))
    _foreign_repo(tmp_path / "project")
    site = tmp_path / "project" / "site"
    subprocess.run([sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(site), str(wheel)],
                   check=True, capture_output=True, timeout=300)
    assert (site / "evaluation" / "_build_info.json").exists()
    child = ("import evaluation.provenance as p, lawn_env, gymnasium as gym; gym.make('lawn/Joint-v1').reset(seed=0); "
             "print(p.__file__); print(p.provenance())")
    env = dict(os.environ, PYTHONPATH=str(site), NUMBA_CACHE_DIR=str(tmp_path / "cache"))
    out = subprocess.run([sys.executable, "-c", child], cwd=tmp_path / "project", env=env, capture_output=True,
                         text=True, check=True, timeout=300).stdout.splitlines()
    assert out[0].startswith(str(site))  # the installed copy, not this checkout
    assert out[1].split("commit ")[1].split()[0] == _git(ROOT, "rev-parse", "--short=10", "HEAD")
    assert any((tmp_path / "cache").rglob("*.nbi")) and not any(site.rglob("*.nbi"))
