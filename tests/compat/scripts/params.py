"""Parameters: list, read, write through Ros and Param."""
import os
import time

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()
name = os.environ["PARAM"]

deadline = time.time() + 30
while name not in client.get_params() and time.time() < deadline:
    time.sleep(0.2)
print("listed:", name in client.get_params())
print("value:", client.get_param(name))
param = roslibpy.Param(client, name)
param.set(2.5)
print("after set:", param.get(timeout=10))
try:
    param.delete(timeout=10)
    print("deleted:", name not in client.get_params())
except Exception as error:
    print("delete refused:", type(error).__name__, error)
client.terminate()
