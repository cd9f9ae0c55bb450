"""mm-monitor: the Qt monitor of Mouse Monitor for ROS 2.

Layers (see docs/monitor.md):

* :mod:`.readings`, :mod:`.history`, :mod:`.session` -- pure Python/numpy: what a
  reply of mm_beagle holds, the columnar history, and the processing pipeline
  (deltas from totals, median filters, calibration, pose math). No Qt, no ROS.
* :mod:`.ros_bridge` -- rclpy spun in its own thread; async service calls;
  results handed to the GUI thread by Qt signals.
* the widget modules -- draw and forward user intent only.
"""
