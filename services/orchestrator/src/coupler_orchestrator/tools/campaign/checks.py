"""The [checks] of a campaign file: true/false columns over a run's outputs, derived values and
parameters — names, numbers, arithmetic, comparisons and/or/not, evaluated without eval."""

from __future__ import annotations

import ast
import operator
from collections.abc import Callable, Mapping, Sequence
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from coupler_orchestrator.tools.campaign.model import Check


class ExpressionError(ValueError):
    """A check that is not an expression this module evaluates (the reason, for the file's
    error)."""


_OPERATORS: dict[type, Callable[..., Any]] = {
    ast.Add: operator.add,
    ast.Sub: operator.sub,
    ast.Mult: operator.mul,
    ast.Div: operator.truediv,
    ast.USub: operator.neg,
    ast.Not: operator.not_,
    ast.Eq: operator.eq,
    ast.NotEq: operator.ne,
    ast.Lt: operator.lt,
    ast.LtE: operator.le,
    ast.Gt: operator.gt,
    ast.GtE: operator.ge,
}


LONGEST = 1000
"""Characters a check's expression may have."""

_ALLOWED = (
    ast.BoolOp,
    ast.And,
    ast.Or,
    ast.BinOp,
    ast.UnaryOp,
    ast.Compare,
    ast.Name,
    ast.Load,
    ast.Constant,
)


class Expression:
    """A check's expression: names, numbers, texts, arithmetic on numbers, comparisons,
    and/or/not; nothing else (no calls, no attributes, no powers, no arithmetic on texts),
    evaluated without eval, so a check costs no more than its length."""

    def __init__(self, text: str) -> None:
        if len(text) > LONGEST:
            raise ExpressionError(f"it has {len(text):,} characters, more than {LONGEST}")
        try:
            self.tree = ast.parse(text, mode="eval").body
        except SyntaxError as exc:
            raise ExpressionError(f"not an expression ({exc.msg})") from None
        except (RecursionError, MemoryError):
            raise ExpressionError("not an expression (nested too deeply)") from None
        for node in ast.walk(self.tree):
            if not isinstance(node, _ALLOWED) and type(node) not in _OPERATORS:
                raise ExpressionError(f"{type(node).__name__} is not allowed")
            if isinstance(node, ast.Constant) and not isinstance(node.value, (int, float, str)):
                raise ExpressionError(f"{ast.unparse(node)} is not a number or a text")
            operands = (
                [node.left, node.right]
                if isinstance(node, ast.BinOp)
                else [node.operand]
                if isinstance(node, ast.UnaryOp) and not isinstance(node.op, ast.Not)
                else []
            )
            if any(isinstance(o, ast.Constant) and isinstance(o.value, str) for o in operands):
                raise ExpressionError(
                    f"{ast.unparse(node)}: a text cannot be computed with; compare texts with "
                    "== or !="
                )

    def evaluate(self, names: Mapping[str, Any]) -> Any:
        return self._value(self.tree, names)

    def _value(self, node: ast.expr, names: Mapping[str, Any]) -> Any:
        if isinstance(node, ast.Constant):
            return node.value
        if isinstance(node, ast.Name):
            if names.get(node.id) is None:
                raise KeyError(node.id)
            return names[node.id]
        if isinstance(node, ast.BoolOp):
            values = (self._value(v, names) for v in node.values)
            return all(values) if isinstance(node.op, ast.And) else any(values)
        if isinstance(node, ast.UnaryOp):
            operand = self._value(node.operand, names)
            if not isinstance(node.op, ast.Not):
                _number(operand)
            return _OPERATORS[type(node.op)](operand)
        if isinstance(node, ast.BinOp):
            return _OPERATORS[type(node.op)](
                _number(self._value(node.left, names)), _number(self._value(node.right, names))
            )
        assert isinstance(node, ast.Compare)
        left = self._value(node.left, names)
        for op, right_node in zip(node.ops, node.comparators, strict=True):
            right = self._value(right_node, names)
            if not _OPERATORS[type(op)](left, right):
                return False
            left = right
        return True


def _number(value: Any) -> Any:
    """Arithmetic is on numbers only: a parameter or output that is a text is no operand (a
    text times a large number would be a large text)."""
    if not isinstance(value, (int, float)):
        raise TypeError(f"{value!r} is not a number")
    return value


def evaluate_checks(checks: Sequence[Check], values: Mapping[str, Any]) -> dict[str, bool | None]:
    """Each check's truth over ``values``; None when a name it uses has no value (a failed
    run, an output missing)."""
    found: dict[str, bool | None] = {}
    for check in checks:
        try:
            found[check.name] = bool(Expression(check.expression).evaluate(values))
        except (KeyError, TypeError, ZeroDivisionError, OverflowError):
            found[check.name] = None
    return found
