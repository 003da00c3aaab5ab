"""Robot recordings in: ROS 1 ``.bag``, ROS 2 bags (``.db3``) and ``.mcap``, without a ROS install.

Built on the ``rosbags`` library. Streams come as arrays in SI units with both
clocks (header stamp, receive time); the tf tree is resolved between any two
frames at any stamps; images are decoded only for the frames used. Every
problem with a file (damaged, truncated, unindexed, a missing topic or frame)
is one :class:`~robocal.errors.RobocalError` line naming the file. See docs/bags.md.
"""

from robocal.bags._reader import *  # noqa: F401,F403
from robocal.bags._tf import *  # noqa: F401,F403
from robocal.bags._messages import *  # noqa: F401,F403
from robocal.bags._inspect import *  # noqa: F401,F403
from robocal.bags._simulate import *  # noqa: F401,F403
from robocal.bags._simulate_handeye import *  # noqa: F401,F403
from robocal.bags._api import *  # noqa: F401,F403
from robocal.bags import _api, _inspect, _messages, _reader, _simulate, _simulate_handeye, _tf

__all__ = [*_reader.__all__, *_tf.__all__, *_messages.__all__, *_inspect.__all__, *_simulate.__all__,
           *_simulate_handeye.__all__, *_api.__all__]
