"""``robocal bag inspect FILE``: what is in a robot recording (declarations only; the work is in robocal.bags)."""

from __future__ import annotations

from pathlib import Path

from robocal.cli._common import RawHelp, add_command, examples_epilog


def add_bag_command(sub) -> None:
    """``robocal bag inspect FILE``: topics, types, counts, rates, time span, gaps, clocks and the tf tree."""
    def build(bag):
        cmds = bag.add_subparsers(dest="bag_command", metavar="COMMAND")
        p = cmds.add_parser(
            "inspect", help="topics, message types, counts, rates, time span, gaps, clocks and the tf tree",
            description="Prints what a user needs to choose topics and frames: each topic's message type, count,\n"
                        "rate and clock (receive time minus header stamp, flagged when the sender stamps on\n"
                        "another clock), the pauses longer than 3x a topic's median period, and the tf tree\n"
                        "(frames, parents, static or dynamic, rate). Reads every message's stamps, decodes none\n"
                        "but tf's.", formatter_class=RawHelp,
            epilog=examples_epilog("robocal bag inspect examples/bags/sim.bag",
                                   "robocal bag inspect rosbag2_2024_05_01-10_00_00/   # a ROS 2 bag folder",
                                   "robocal bag inspect run.mcap"))
        p.add_argument("input", type=Path, metavar="FILE",
                       help="a .bag file, a ROS 2 bag folder, a .db3 or a .mcap file")
        p.add_argument("--no-progress", action="store_true", help="never show progress bars")
        p.set_defaults(func=_inspect)
        bag.set_defaults(func=lambda a: (bag.print_help(), 0)[1])

    add_command(
        sub, "bag", build, help="read ROS 1 .bag, ROS 2 .db3 and .mcap recordings (no ROS install needed)",
        description="Commands on robot recordings: ROS 1 .bag files, ROS 2 bags (the folder, or its .db3 /\n"
                    ".mcap file) and MCAP files. See docs/bags.md.", formatter_class=RawHelp)


def _inspect(args) -> int:
    from robocal.bags import inspect_recording

    print(inspect_recording(args.input, show_progress=not args.no_progress).text())
    return 0
