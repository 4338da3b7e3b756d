"""How a p-value is written on a console line or in a verdict (pure Python: the report's verdicts import it)."""
from __future__ import annotations


def p_text(p: float) -> str:
    """``p = 0.0123``; ``p < 1e-300`` where the tail probability is below what a double holds (it underflows to 0,
    and "p = 0" would read as an impossible certainty)."""
    return "p < 1e-300" if p < 1e-300 else f"p = {p:.3g}"
