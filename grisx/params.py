"""Method options: the ``--param name=value`` of toy problems and render methods, declared once.

A :class:`Param` carries its type, default, range and one line of documentation; the
toy framework and the render registry both parse ``--param`` values through it, so
every option of every method is checked the same way and a bad value is one line
naming the param and its owner.
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

from grisx.errors import INT32_MAX, InvalidParameterError

__all__ = ["Param"]

#: the largest finite float32 (kernels compute in float32)
FLOAT32_MAX = 3.4028234663852886e38

_TRUE = {"true", "1", "yes", "on"}
_FALSE = {"false", "0", "no", "off"}


@dataclasses.dataclass(frozen=True)
class Param:
    """A method option (``--param name=value``) with its type, default and range."""

    name: str
    default: Any
    doc: str
    kind: str = "float"  # "int" | "float" | "bool" | "choice"
    choices: tuple[str, ...] = ()
    minimum: float | None = None
    maximum: float | None = None

    def parse(self, value: Any, owner: str) -> Any:
        """Convert a CLI string (or a Python value) and check its range; ``owner`` names who takes it in errors
        (``"toy 'ris-1d'"``, ``"render method 'restir-pt'"``)."""
        where = f"param '{self.name}' of {owner}"
        if self.kind == "bool":
            if isinstance(value, bool):
                return value
            text = str(value).strip().lower()
            if text in _TRUE:
                return True
            if text in _FALSE:
                return False
            raise InvalidParameterError(f"{where} must be true or false, got '{value}'")
        if self.kind == "choice":
            text = str(value).strip()
            if text not in self.choices:
                raise InvalidParameterError(f"{where} must be one of {', '.join(self.choices)}, got '{value}'")
            return text
        try:
            if self.kind == "int":
                if isinstance(value, float) and not value.is_integer():
                    raise ValueError
                number: float = int(str(value).strip()) if isinstance(value, str) else int(value)
            else:
                number = float(value)
        except (TypeError, ValueError):
            raise InvalidParameterError(f"{where} must be {'an integer' if self.kind == 'int' else 'a number'}, got '{value}'") from None
        if not math.isfinite(number):
            raise InvalidParameterError(f"{where} must be finite, got '{value}'")
        if self.minimum is not None and number < self.minimum:
            raise InvalidParameterError(f"{where} must be >= {self.minimum:g}, got {number:g}")
        if self.maximum is not None and number > self.maximum:
            raise InvalidParameterError(f"{where} must be <= {self.maximum:g}, got {number:g}")
        if self.kind == "int" and not -INT32_MAX - 1 <= number <= INT32_MAX:  # kernels take int32: it would wrap
            raise InvalidParameterError(f"{where} must be within 32-bit integers [-2^31, 2^31 - 1], got {number}")
        if self.kind == "float" and abs(number) > FLOAT32_MAX:  # kernels take float32: it would be Inf
            raise InvalidParameterError(f"{where} must be within float32's range (|x| <= 3.4e38), got {number:g}")
        return number

    def describe(self) -> dict[str, Any]:
        out = {"name": self.name, "type": self.kind, "default": self.default, "doc": self.doc}
        if self.choices:
            out["choices"] = list(self.choices)
        if self.minimum is not None:
            out["min"] = self.minimum
        if self.maximum is not None:
            out["max"] = self.maximum
        return out
