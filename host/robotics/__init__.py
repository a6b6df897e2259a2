"""Recordings for the tools robotics and video users already run: ROS 2 messages in MCAP, ROS 2 and ROS 1 bags
(Kalibr's layout among them) and Gyroflow's ``.gcsv`` gyro log beside an H.264 video.

The bag and MCAP writers need the ``robotics`` extra (``mcap``, ``mcap-ros2-support``, ``rosbags``: pure Python,
no ROS install) and import it only when a recording starts; the ``.gcsv`` writer needs nothing beyond rollcam.
"""

from .bags import BAG_FORMATS, KALIBR_TOPICS, OUTPUT, BagWriter, typestore

__all__ = ["BAG_FORMATS", "KALIBR_TOPICS", "OUTPUT", "BagWriter", "typestore"]
