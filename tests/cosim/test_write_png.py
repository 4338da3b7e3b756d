"""What the figures' speed-ups must not change (issue 23, item 5): ``cosim.plots.write_png`` writes the pixels of
matplotlib's own ``tight_layout`` + ``savefig`` without the second layout pass savefig made for tight_layout's
placeholder engine, whatever the rc settings; and ``cosim``'s exit shortcut (the objects frozen out of the last
garbage collection) is the program's only, never an in-process caller's, and the collector paused by
``cosim run`` is given back as it was."""
from __future__ import annotations

import gc

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from PIL import Image  # noqa: E402

from feeddrive.cosim.cli import main  # noqa: E402
from feeddrive.cosim.plots import DPI, write_png  # noqa: E402


def _figure() -> plt.Figure:
    """Two panels with long tick labels, a legend outside and a wrapped title: what tight_layout moves."""
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(4, 3), dpi=DPI)
    t = np.linspace(0.0, 3.5, 50)
    axes[0].plot(t, 1e4 * np.sin(7 * t), label="current [A]")
    axes[1].plot(t, 1e-3 * np.cos(3 * t), label="speed [rad/s]")
    for ax in axes:
        ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1), fontsize=7, frameon=False)
        ax.set_ylabel("a long label [unit]")
    axes[1].set_title("passed: current independence F = 1.08, Bonferroni-adjusted p = 1 >= alpha = 0.01 (5 tests)",
                      fontsize=8, wrap=True)
    fig.suptitle("motion 1: healthy: validated, no drift")
    return fig


def _pixels(path) -> np.ndarray:
    return np.asarray(Image.open(path).convert("RGBA"))


@pytest.mark.parametrize("rc", [{}, {"figure.autolayout": True}])
def test_write_png_draws_the_pixels_of_tight_layout_and_savefig(tmp_path, rc):
    with matplotlib.rc_context(rc):
        reference = _figure()
        reference.tight_layout()
        reference.savefig(tmp_path / "reference.png", dpi=DPI)
        plt.close(reference)
        fig = _figure()
        path = write_png(fig, tmp_path / "sub" / "fast.png")
    assert path == tmp_path / "sub" / "fast.png"
    if not rc:  # no layout pass at savefig (with autolayout, savefig itself sets the tight engine again)
        assert fig.get_layout_engine() is None
    assert not plt.fignum_exists(fig.number)  # closed
    a, b = _pixels(tmp_path / "reference.png"), _pixels(path)
    assert a.shape == b.shape == (3 * DPI, 4 * DPI, 4)
    np.testing.assert_array_equal(a, b)


def test_write_png_keeps_a_layout_made_by_the_caller(tmp_path):
    """``layout=False`` (cosim.trends: tight_layout with a rect for the figure legend) keeps the caller's layout."""
    fig = _figure()
    fig.tight_layout(rect=(0, 0.1, 1, 1))
    bottom = fig.subplotpars.bottom
    write_png(fig, tmp_path / "trends.png", dpi=100, layout=False)
    assert fig.subplotpars.bottom == bottom and bottom > 0.1
    assert _pixels(tmp_path / "trends.png").shape == (300, 400, 4)


def test_cli_freezes_the_heap_only_when_it_is_the_program(tmp_path, capsys):
    before = gc.get_freeze_count()
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0 and "cosim" in capsys.readouterr().out
    missing = tmp_path / "none.sqlite"
    assert main(["history", "--axis", "X", "--db", str(missing)]) == 2  # the status, returned to the caller
    assert f"{missing} does not exist" in capsys.readouterr().err
    assert gc.get_freeze_count() == before


@pytest.mark.parametrize("collecting", [True, False])
def test_cosim_run_gives_the_collector_back_as_it_found_it(tmp_path, capsys, collecting):
    """``cosim run`` turns the collector off while it imports and loads the scenario: its state is the caller's
    again afterwards, also when the scenario is bad (exit 2)."""
    path = tmp_path / "bad.yaml"
    path.write_text("name: bad\nstep: -1\nnc: {program: []}\n")
    (gc.enable if collecting else gc.disable)()
    try:
        assert main(["run", str(path), "--out", str(tmp_path / "out"), "--no-progress"]) == 2
        assert gc.isenabled() is collecting
    finally:
        gc.enable()
    assert "step: Input should be greater than 0" in capsys.readouterr().err


@pytest.mark.parametrize("width", [2.5, 9.0])
def test_wrapped_breaks_the_lines_where_matplotlib_does(width):
    """``cosim.plots.wrapped`` (a bisection per line) gives matplotlib's own lines (one more word at a time), for
    a title over an axes and a figure title, texts with line breaks of their own, a word wider than the figure."""
    from feeddrive.cosim.plots import wrapped

    texts = ["passed: current independence F = 1.08, Bonferroni-adjusted p = 1 >= alpha = 0.01 (5 tests)\n"
             "current RMS 0.0312 vs noise 0.05; speed RMS 0.00121 vs noise 0.002, noise not checked: no confirmed "
             "redundant speed pair", "short", "", "averyveryverylongwordwithoutanyspaceinsideitatallreallywideindeed x",
             "two  spaces  between words and a trailing space "]
    fig, ax = plt.subplots(figsize=(width, 3), dpi=DPI)
    made = [wrapped(ax.set_title(text, fontsize=8, wrap=True)) for text in texts[:1]]
    made += [wrapped(fig.text(0.3, 0.5, text, fontsize=9, wrap=True)) for text in texts]
    made.append(wrapped(fig.suptitle(texts[0], fontsize=10, wrap=True)))
    fig.canvas.draw()  # each text's renderer and position: what the wrapping measures against
    for text in made:
        ours, theirs = text._get_wrapped_text(), matplotlib.text.Text._get_wrapped_text(text)
        assert ours == theirs
        assert ours.replace("\n", " ") == text.get_text().replace("\n", " ")  # line breaks only
    assert max(t._get_wrapped_text().count("\n") for t in made) >= (3 if width < 5 else 1)  # some were wrapped
    plt.close(fig)


def test_tight_layout_measuring_each_axes_once_places_them_as_matplotlib_does():
    """``cosim.plots.tight_layout`` (the trends: ``rect`` makes matplotlib lay out twice from the same extents) puts
    every Axes where ``Figure.tight_layout`` does, and leaves the Axes' own ``get_tightbbox`` in place."""
    from feeddrive.cosim.plots import tight_layout

    def figure() -> plt.Figure:
        fig, axes = plt.subplots(2, 2, sharex=True, figsize=(5, 4), dpi=100)
        for k, ax in enumerate(axes.ravel()):
            ax.plot([1, 2, 3], [10.0 ** k, 3.0 * 10.0 ** k, 2.0 * 10.0 ** k], "o-", label="estimate")
            ax.set_ylabel(f"parameter {k} [unit{'s' * k}]")
        axes[1, 0].set_xlabel("motion number (history order)")
        fig.legend(*axes[0, 0].get_legend_handles_labels(), loc="lower center", frameon=False)
        fig.suptitle("parameter trends axis X")
        return fig

    theirs, ours = figure(), figure()
    theirs.tight_layout(rect=(0, 0.06, 1, 1))
    tight_layout(ours, rect=(0, 0.06, 1, 1))
    assert [ax.get_position().bounds for ax in ours.axes] == [ax.get_position().bounds for ax in theirs.axes]
    assert all("get_tightbbox" not in vars(ax) for ax in ours.axes)
    plt.close(theirs)
    plt.close(ours)
