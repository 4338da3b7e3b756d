"""The HTML report: one self-contained page per run and per axis history (see ``page``)."""
from feeddrive.cosim.report.page import PAGE, render_run, write_history_page, write_run_page

__all__ = ["PAGE", "render_run", "write_history_page", "write_run_page"]
