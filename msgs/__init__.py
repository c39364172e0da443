"""Interface definitions, their pure-Python parser and generator, and typed classes.

``msgs.runtime`` holds the message base class and :func:`msgs.runtime.lookup`; the
generated packages are ``msgs.<pkg>.msg``, ``msgs.<pkg>.srv`` and ``msgs.<pkg>.action``
(for example ``from msgs.std_msgs.msg import String``). Nothing here imports ROS.
"""
