"""The JSON summary every stage returns (and the CLI prints on stdout)."""

from __future__ import annotations

import json
from typing import Any


def jsonable(obj: Any) -> Any:
    """``json.dumps``'s ``default``: numpy scalars and arrays as Python values, the rest
    as text."""
    try:
        import numpy as np

        if isinstance(obj, np.generic):
            return obj.item()
        if isinstance(obj, np.ndarray):
            return obj.tolist()
    except ImportError:  # pragma: no cover
        pass
    return str(obj)


def summary_text(summary: dict[str, Any]) -> str:
    """The summary as the CLI prints it: indented JSON, keys sorted."""
    return json.dumps(summary, indent=2, sort_keys=True, default=jsonable)
