"""The HTML report: one self-contained page per run and per axis history (see ``page``).

``page`` (jinja2) is imported on first use: the console summaries import only ``verdict``.
"""
from __future__ import annotations

__all__ = ["PAGE", "prepare", "render_run", "write_history_page", "write_run_page"]


def __getattr__(name: str):  # noqa: ANN202 - lazy re-exports of ``page``
    if name in __all__:
        from feeddrive.cosim.report import page

        return getattr(page, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
