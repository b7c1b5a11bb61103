"""Sphinx configuration of the lawn docs site (``bash scripts/docs.sh`` builds it into ``site/``)."""

import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))

import lawn_env  # noqa: E402

project = "lawn"
author = "the lawn developers"
release = version = lawn_env.__version__
copyright = "2026, the lawn developers"

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.intersphinx",
    "lawn_docs",
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "sweeps", "learned/*.csv"]

myst_enable_extensions = ["colon_fence", "dollarmath"]
myst_heading_anchors = 3  # `page.md#a-heading` links
smartquotes = False  # "--set" stays two hyphens, quotes stay straight (command lines are quoted as written)

# each object documented where it is defined (a package's re-exports are not documented twice)
autodoc_default_options = {"members": True, "undoc-members": False, "show-inheritance": False,
                           "ignore-module-all": True}
autodoc_inherit_docstrings = False  # Gymnasium's and PettingZoo's own docstrings are theirs to render
autodoc_typehints = "description"
autodoc_member_order = "bysource"
# the rl and data extras are not part of the docs extra: their modules are documented without them
autodoc_mock_imports = ["torch", "stable_baselines3", "sb3_contrib", "supersuit", "minari", "ray", "tensorboard"]
intersphinx_mapping = {}  # the build reads no other site (it must pass offline)

html_theme = "furo"
html_title = f"lawn {release}"
html_static_path = []
html_show_sourcelink = False
html_theme_options = {"source_repository": "", "navigation_with_keys": True}

#: The environment classes' docstrings are Gymnasium-style Markdown, rendered on their pages.
ENV_PAGES = {"lawn_env.envs.joint.JointEnv": "/envs/joint", "lawn_env.envs.comm.CommEnv": "/envs/comm",
             "lawn_env.envs.parallel.LawnParallelEnv": "/envs/parallel"}


def _env_docstring(app, what, name, obj, options, lines):
    if name in ENV_PAGES:
        lines[:] = [f"The environment's documentation: :doc:`{ENV_PAGES[name]}`.", ""]


def setup(app):
    app.connect("autodoc-process-docstring", _env_docstring)


# strict: scripts/docs.sh runs sphinx-build -W --keep-going (every warning fails the build)
nitpicky = False
