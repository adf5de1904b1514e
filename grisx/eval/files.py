"""Study outputs on disk: JSON, CSV and PNG written atomically (a temporary file renamed into place).

A failed or interrupted write leaves no half-written file behind. JSON has no
NaN or Inf: :func:`plain` turns them (and numpy scalars and arrays) into
``null`` and plain Python values.
"""

from __future__ import annotations

import csv
import io
import json
import math
import os
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["plain", "json_line", "write_atomic", "write_json", "write_csv"]


def plain(x: Any) -> Any:
    """JSON-ready copy: numpy → Python, non-finite floats → None, paths → str."""
    if isinstance(x, dict):
        return {str(k): plain(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [plain(v) for v in x]
    if isinstance(x, np.ndarray):
        return plain(x.tolist())
    if isinstance(x, np.integer):
        return int(x)
    if isinstance(x, (float, np.floating)):
        return float(x) if math.isfinite(float(x)) else None
    if isinstance(x, Path):
        return str(x)
    return x


def json_line(obj: Any) -> str:
    """One line of strict JSON (numpy → Python, NaN/Inf → null): what every ``--json`` prints."""
    return json.dumps(plain(obj), allow_nan=False, ensure_ascii=False, default=str)


def write_atomic(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` through a temporary file in the same directory; return the path."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_json(path: str | os.PathLike, data: Mapping[str, Any]) -> Path:
    return write_atomic(path, (json.dumps(plain(dict(data)), indent=1, ensure_ascii=False) + "\n").encode())


def write_csv(path: str | os.PathLike, rows: Sequence[Mapping[str, Any]], columns: Sequence[str]) -> Path:
    """One row per mapping, the given columns in order (missing values empty, extra keys ignored)."""
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=list(columns), extrasaction="ignore")
    w.writeheader()
    for row in rows:
        w.writerow({k: ("" if v is None else v) for k, v in plain(dict(row)).items()})
    return write_atomic(path, buf.getvalue().encode())
