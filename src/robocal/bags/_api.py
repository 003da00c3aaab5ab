"""The two calls the rigs make: images of a topic by name, and poses between two tf frames."""

from __future__ import annotations

from robocal.bags._messages import iter_images
from robocal.bags._tf import PoseStream, read_tf

__all__ = ["images", "poses", "image_name"]


def image_name(topic: str, stamp_ns: int) -> str:
    """``"/camera/image_raw@1700000000.500000000"``: a frame's name, its topic and header stamp [s, 9 decimals]."""
    return f"{topic}@{stamp_ns // 1_000_000_000}.{stamp_ns % 1_000_000_000:09d}"


def images(path, topic: str, stamps=None, *, tolerance: float = 1e-6, show_progress: bool = True):
    """Yield ``(name, image)`` for the frames of ``topic`` (all, or those at ``stamps``), decoded one at a time.

    ``name`` is :func:`image_name` (``topic@stamp``), the key a rig's
    per-view results carry; ``image`` an OpenCV array (mono ``(H, W)``,
    colour ``(H, W, 3)`` BGR). ``stamps``: header stamps (int ns or float s)
    matched within ``tolerance`` [s].
    """
    for stamp, img in iter_images(path, topic, stamps, tolerance=tolerance, show_progress=show_progress):
        yield image_name(topic, stamp), img


def poses(path, parent: str, child: str, stamps=None, *, show_progress: bool = True) -> PoseStream:
    """``T_parent_child`` (N, 4, 4) [m] at ``stamps`` (header clock; int ns or float s), with the interpolation gap.

    Reads the recording's ``/tf`` and ``/tf_static``; see :meth:`TfTree.lookup`.
    """
    return read_tf(path, show_progress=show_progress).lookup(parent, child, stamps)
