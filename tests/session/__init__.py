"""Session-level tests: the Graph port and what runs on it without ROS."""
