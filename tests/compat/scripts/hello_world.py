"""roslibpy's hello world: connect, report, terminate."""
import os

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()
print("Is ROS connected?", client.is_connected)
client.terminate()
