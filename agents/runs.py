"""Run directories on disk (``lawn train`` output, shipped agents): reading their JSON files with
errors that name the file and what is wrong with it."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["read_json"]


def read_json(path: Path, context: str = "", missing: str = "") -> Any:
    """The parsed JSON file at ``path``; a ``ValueError`` naming the file if it is absent
    (with the hint ``missing``) or is not valid JSON (with the line and column)."""
    path = Path(path)
    prefix = f"{context} {path.parent}: " if context else ""
    try:
        text = path.read_text()
    except FileNotFoundError:
        raise ValueError(f"{prefix}no {path.name} in {path.parent}" + (f" ({missing})" if missing else "")) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ValueError(f"{prefix}cannot read {path}: {exc}") from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"{prefix}{path} is not valid JSON (line {exc.lineno}, column {exc.colno}: {exc.msg})") from None
