"""The live ROS 2 bridge (``robofabric ros2``): a user peer, one login, that republishes a world's streams as
ROS 2 topics and turns ``cmd_vel`` / ``joint_command`` into commands for the robots its login owns.

:mod:`user_peer.ros2.bridge` holds the bridge (it imports ``rclpy``); :mod:`user_peer.ros2.fill` fills
``rclpy`` messages from the dicts :func:`user_peer.openfmt.ros2.ros2_message` makes (the MCAP export's
conversion, so names of frames, stamps and values are the same live and in a recording);
:mod:`user_peer.ros2.cli` is the command. docs/ros2.md tells the topics and the limits.
"""
