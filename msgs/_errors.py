"""The errors of the message classes and of type lookup (both exported by :mod:`msgs.runtime`)."""

from __future__ import annotations

_REPR_LIMIT = 40


class ValidationError(ValueError):
    """A value does not fit its field: names the field ``path`` and the ``expected`` type."""

    def __init__(self, path: str, expected: str, problem: str) -> None:
        self.path = path
        self.expected = expected
        self.problem = problem
        where = path or "<message>"
        super().__init__(f"{where}: expected {expected}, {problem}")

    def _under(self, step: str) -> ValidationError:
        """The same error seen from one level up: ``step`` is ``name`` or ``[i]``."""
        if not self.path:
            path = step
        elif self.path.startswith("["):
            path = step + self.path
        else:
            path = f"{step}.{self.path}"
        return ValidationError(path, self.expected, self.problem)


class UnknownTypeError(LookupError):
    """No generated interface type has this name."""

    def __init__(self, type_name: str, reason: str) -> None:
        self.type_name = type_name
        super().__init__(f"unknown interface type {type_name!r}: {reason}")

    def __str__(self) -> str:
        return str(self.args[0])


def _describe(value: object) -> str:
    """A short description of a bad value for error messages (type and a clipped repr).

    A type from outside the builtins is named with its module (``numpy.float32``), so it
    never reads as the field's own type name."""
    text = repr(value)
    if len(text) > _REPR_LIMIT:
        text = text[: _REPR_LIMIT - 3] + "..."
    kind = type(value)
    name = kind.__name__ if kind.__module__ == "builtins" else f"{kind.__module__}.{kind.__name__}"
    return f"got {name} {text}"
