"""``validation.json``: strict JSON (RFC 8259) that any parser reads.

Python's :mod:`json` writes ``nan``, ``inf`` and ``-inf`` as the tokens ``NaN``, ``Infinity``
and ``-Infinity``, which are not JSON: JavaScript's ``JSON.parse`` and other strict parsers
reject the whole file. The report's numbers are not all finite (the total path gain of a
receiver no path reaches is -inf dB, a coverage cell that one engine does not reach has a NaN
difference), so :func:`json_safe` writes every non-finite number as ``null``, at any depth,
and :func:`write_json` refuses anything else that is not plain JSON instead of guessing.

A reader turns ``null`` back into NaN with ``np.asarray(values, dtype=float)``.
"""

from __future__ import annotations

import json
import math

import numpy as np


def json_safe(obj, where: str = "summary"):
    """A copy of ``obj`` made of plain JSON values, with ``None`` for every non-finite number.

    Parameters
    ----------
    obj : dict, list, tuple, numpy array, number, str, bool or None
        Dictionaries must have string keys. Numpy arrays and scalars become lists and
        Python numbers.
    where : str
        Where ``obj`` sits in the document, for the error message.

    Raises
    ------
    TypeError
        For a value JSON cannot hold (a complex number, an object), naming where it is.
    """
    if obj is None or isinstance(obj, str):
        return obj
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (int, np.integer)):
        return int(obj)
    if isinstance(obj, (float, np.floating)):
        x = float(obj)
        return x if math.isfinite(x) else None
    if isinstance(obj, np.ndarray):
        return json_safe(obj.tolist(), where)
    if isinstance(obj, dict):
        out = {}
        for k, v in obj.items():
            if not isinstance(k, str):
                raise TypeError(f"`{where}` must have string keys, got {k!r}")
            out[k] = json_safe(v, f"{where}[{k!r}]")
        return out
    if isinstance(obj, (list, tuple)):
        return [json_safe(v, f"{where}[{i}]") for i, v in enumerate(obj)]
    raise TypeError(f"`{where}` must be a JSON value (number, string, bool, None, list, dict), "
                    f"got {type(obj).__name__}")


def write_json(obj, path: str) -> None:
    """Write ``obj`` to ``path`` as strict JSON (:func:`json_safe`; ``allow_nan=False``)."""
    with open(path, "w") as f:
        json.dump(json_safe(obj), f, indent=1, allow_nan=False)
        f.write("\n")
