"""The verification chart (issue 24): log scale with the noise-floor line, corrected/held counts in the labels,
the corrected points' RMS beside all points' where a pass held some."""
import pytest

pytest.importorskip("matplotlib")

from campaign.correct.verify_report import VerifyReport  # noqa: E402
from campaign.report import html_figures  # noqa: E402


def _verify() -> VerifyReport:
    stage = lambda rms, n: {"max_mm": 2 * rms, "mean_mm": rms, "rms_mm": rms, "n": n}  # noqa: E731
    names = ("uncorrected (planned joints)", "model-corrected", "closed loop 1")
    stages = dict(zip(names, (stage(0.78, 27), stage(0.035, 27), stage(0.031, 27))))
    passes = [{"stage": names[0], "n_corrected": 0, "n_held": 27, "held": {}, "all": stages[names[0]],
               "corrected": None},
              {"stage": names[1], "n_corrected": 24, "n_held": 3, "held": {"bound": 3}, "all": stages[names[1]],
               "corrected": stage(0.029, 24)},
              {"stage": names[2], "n_corrected": 27, "n_held": 0, "held": {}, "all": stages[names[2]],
               "corrected": stage(0.031, 27)}]
    return VerifyReport.from_dict({"format": "campaign-verify/2", "run": "run", "n": 27, "noise_floor_mm": 0.03,
                                   "n_uncorrected": 0, "stages": stages, "passes": passes, "exit_status": "success",
                                   "reason": "", "definitions": {}, "created_utc": "2026-11-26T10:00:00Z"})


@pytest.mark.unit
def test_verify_chart_is_log_scale_with_the_floor_and_the_counts(monkeypatch):
    drawn = []
    monkeypatch.setattr(html_figures, "_png", lambda fig: drawn.append(fig) or b"png")
    fig = html_figures.verify_figure(_verify(), 0)
    assert fig.png == b"png" and "log scale" in fig.caption
    ax = drawn[0].axes[0]
    assert ax.get_yscale() == "log"
    floor = [line for line in ax.get_lines() if line.get_label().startswith("noise floor")]
    assert len(floor) == 1 and floor[0].get_ydata()[0] == pytest.approx(0.03)
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels[0].endswith("0 corrected, 27 held") and labels[1].endswith("24 corrected, 3 held")
    lo, hi = ax.get_ylim()
    assert lo < 0.029 and hi > 0.78                            # every bar and the floor inside the axis
    heights = sorted(round(p.get_height(), 3) for p in ax.patches if p.get_height() == p.get_height())
    assert heights == [0.029, 0.031, 0.035, 0.78]              # corrected-only bar only where points were held
