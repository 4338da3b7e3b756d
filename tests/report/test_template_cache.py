"""report.html's compiled template is cached on disk (jinja2 bytecode): the same page from the cache, a new
compilation when the template changes, and the page still written when the cache cannot be used."""
from __future__ import annotations

import jinja2

from feeddrive.cosim.report import page

REPORT = {"scenario": "cache-check", "status": "ok", "stop_time_s": 1.5, "wall_time_s": 0.2, "motions": []}


def _env() -> jinja2.Environment:
    """A fresh environment like the page's (nothing compiled in memory yet)."""
    env = page._ENV.overlay()
    env.cache = jinja2.environment.create_cache(400)
    return env


def test_compiled_once_then_loaded(tmp_path, monkeypatch):
    monkeypatch.setenv("FEEDDRIVE_CACHE", str(tmp_path))
    first = _env().get_template("report.html.j2")
    assert len(list((tmp_path / "jinja2").glob("report-*.cache"))) == 1
    env = _env()

    def no_compiling(*args, **kwargs):
        raise AssertionError("compiled again although cached")

    env.compile = no_compiling
    second = env.get_template("report.html.j2")
    assert second.render(report=REPORT, kind="run") == first.render(report=REPORT, kind="run")


def test_unusable_cache_still_renders(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    monkeypatch.setenv("FEEDDRIVE_CACHE", str(blocker))  # the cache directory cannot be made
    html = _env().get_template("report.html.j2").render(report=REPORT, kind="run")
    assert "cache-check" in html

    monkeypatch.setenv("FEEDDRIVE_CACHE", str(tmp_path))
    _env().get_template("report.html.j2")
    (entry,) = (tmp_path / "jinja2").glob("report-*.cache")
    entry.write_bytes(entry.read_bytes()[:20])  # truncated: compiled again and rewritten
    assert _env().get_template("report.html.j2").render(report=REPORT, kind="run") == html
    assert entry.stat().st_size > 20
