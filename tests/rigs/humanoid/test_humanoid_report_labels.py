"""The per-view RMS chart with the names frames get from a recording (topic@stamp)."""

import io
import warnings

import matplotlib

matplotlib.use("Agg")

from robocal.bags import image_name  # noqa: E402
from robocal.rigs.humanoid.report import plot_view_rms  # noqa: E402


def test_recorded_frame_names_keep_the_chart_drawable():
    # 12 frames of one topic: before, the full names (38 characters, rotated) left the axes no height and
    # saving warned "constrained_layout not applied because axes sizes collapsed to zero"
    names = [image_name("/nao_robot/camera/top/camera/image_raw", 1_700_000_000_500_000_000 + k * 250_000_000)
             for k in range(12)]
    ax = plot_view_rms(names, ["left", "right"] * 6, [0.1 + 0.01 * k for k in range(12)])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        ax.figure.savefig(io.BytesIO(), format="png", dpi=60)
    labels = [t.get_text() for t in ax.get_xticklabels()]
    assert labels[0] == "1700000000.500000000" and labels[-1] == "1700000003.250000000"
    assert ax.get_xlabel() == "view (/nao_robot/camera/top/camera/image_raw@...)"


def test_plain_view_names_are_kept():
    ax = plot_view_rms(["view_00.png", "view_01.png"], ["left", "right"], [0.2, 0.3])
    assert [t.get_text() for t in ax.get_xticklabels()] == ["view_00.png", "view_01.png"]
