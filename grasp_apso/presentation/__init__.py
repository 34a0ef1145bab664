"""What both front ends (``tools/`` without ROS, ``ros/``) show of a grasp: the printed
summary and verdict (:mod:`.summary`) and the colours of every picture (:mod:`.palette`)."""
