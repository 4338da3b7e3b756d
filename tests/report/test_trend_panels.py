"""The trend figure has a panel for each parameter the axis gives and no empty one: a PMSM's L_d, L_q and psi_f (its
demagnetisation parameter was not drawn at all), a torque-only axis's ft and Cd (four empty slots before)."""
from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pytest  # noqa: E402

from feeddrive.cosim.trends import trend_figure  # noqa: E402

DC = {"R": ("Ohm", 0.6), "L": ("H", 4e-3), "K": ("N.m/A", 1.05), "Jt": ("kg.m2", 0.1), "ft": ("N.m.s/rad", 0.02),
      "Cd": ("N.m", 1.2)}
PMSM = {"R": ("Ohm", 0.7), "L_d": ("H", 8e-3), "L_q": ("H", 8e-3), "psi_f": ("Wb", 0.23), "Jt": ("kg.m2", 3e-3),
        "ft": ("N.m.s/rad", 1.5e-3), "Cd": ("N.m", 0.4)}


def motions(params: dict, n: int = 3) -> list[dict]:
    return [{"motion": 1, "time": 1.7e9 + 60 * k, "validated": True,
             "parameters": {name: {"value": v * (1 + 0.01 * k), "std": 0.001 * v, "ci95": [0.99 * v, 1.01 * v],
                                   "unit": unit} for name, (unit, v) in params.items()}} for k in range(n)]


def panels(fig) -> list[tuple[str, bool]]:
    """(y label, x tick labels shown) of each visible panel, column by column."""
    axes = sorted((ax for ax in fig.axes if ax.get_visible()), key=lambda ax: (ax.get_position().x0, -ax.get_position().y0))
    return [(ax.get_ylabel(), any(t.get_visible() and t.get_text() for t in ax.get_xticklabels())) for ax in axes]


@pytest.mark.parametrize(("params", "expected"), [
    (DC, ["R [Ohm]", "L [H]", "K [N.m/A]", "Jt [kg.m2]", "ft [N.m.s/rad]", "Cd [N.m]"]),
    (PMSM, ["R [Ohm]", "L_d [H]", "L_q [H]", "psi_f [Wb]", "Jt [kg.m2]", "ft [N.m.s/rad]", "Cd [N.m]"]),
    ({"ft": DC["ft"], "Cd": DC["Cd"]}, ["ft [N.m.s/rad]", "Cd [N.m]"]),
], ids=["dc", "pmsm", "torque-only"])
def test_one_panel_per_parameter_and_a_time_axis_under_each_column(params, expected):
    fig = trend_figure(motions(params), "axis X", x="motion")
    fig.canvas.draw()
    shown = panels(fig)
    plt.close(fig)
    assert [label for label, _ in shown] == expected
    assert sum(not ax.get_visible() for ax in fig.axes) == len(expected) % 2 * (len(expected) > 3)  # no blank area
    # the lowest panel of each column carries the motion numbers; the ones above share them
    columns: dict[float, list] = {}
    for ax in (a for a in fig.axes if a.get_visible()):
        columns.setdefault(round(ax.get_position().x0, 3), []).append(ax)
    for col in columns.values():
        lowest = min(col, key=lambda ax: ax.get_position().y0)
        assert lowest.get_xlabel() == "motion number (history order)"
        assert any(t.get_text() for t in lowest.get_xticklabels())


@pytest.mark.parametrize(("params", "expected"), [(DC, list(DC)), (PMSM, list(PMSM)), ({"ft": DC["ft"]}, ["ft"])],
                         ids=["dc", "pmsm", "ft-only"])
def test_the_history_table_has_a_column_per_given_parameter(params, expected, tmp_path):
    """A DC axis's motion table had L_d, L_q, psi_f and T0 columns of dashes; a PMSM's L and K (found by audit2)."""
    import re

    from feeddrive.cosim.report.page import write_history_page

    page = write_history_page(tmp_path / "h.html", "X", motions(params), None, "h.sqlite").read_text()
    header = re.search(r"<tr><th>#</th>.*?</tr>", page).group(0)
    assert re.findall(r"<th>(\w+) \[", header) == expected


def test_the_history_page_states_the_baseline_size_the_monitor_used(tmp_path):
    """examples/pmsm_monitor.yaml learns its baseline from one motion; its history page said 'the first 3' (the
    default), as if the baseline were still being learnt. The size is stored with each judged motion."""
    from feeddrive.cosim.cli.history import thresholds
    from feeddrive.cosim.report.page import write_history_page
    from feeddrive.estimator.history import History

    db = tmp_path / "h.sqlite"
    first, second = motions(DC, 2)
    second["drift_reference"] = {"z_crit": 2.576, "min_relative": {n: 0.02 for n in DC}, "baseline": {n: {"value": v, "std": 1e-3 * v} for n, (_, v) in DC.items()},
                                 "baseline_mode": "motions", "baseline_motions": 1}
    with History(db) as h:
        h.record("X", first, time=first["time"])
        h.record("X", second, time=second["time"])
        stored = h.motions("X")
    t = thresholds(db, "X", stored)
    assert t["baseline_motions"] == 1 and t["baseline_learnt"] == 1
    page = write_history_page(tmp_path / "h.html", "X", stored, t, str(db)).read_text()
    assert "The healthy baseline is the first validated motion without a diagnosis." in page
