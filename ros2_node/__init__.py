"""ROS 2 adapter for flexmb (rclpy): the node, the command player, live replay and the demo.

Imported only by the verbs that need ROS (``flexmb node|play|demo|replay-live``); rclpy loads inside
them. Everything else the node uses (the twin runner, messages, topics, recordings, rerun) is
:mod:`flexmb_io`, which needs no ROS.
"""
