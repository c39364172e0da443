"""Reconnect events: 'ready' and 'close' as the bridge goes away and comes back; topics resume."""
import os
import threading
import time

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
readies = []
resumed = threading.Event()


def on_ready(*args):
    readies.append(time.time())
    print("ready", len(readies), flush=True)


client.on("ready", on_ready)
client.on("close", lambda *args: print("closed", flush=True))
client.run()

listener = roslibpy.Topic(client, os.environ["TOPIC"], "std_msgs/Int32")
listener.subscribe(lambda message: resumed.set() if len(readies) >= 2 else None)
talker = roslibpy.Topic(client, os.environ["TOPIC"], "std_msgs/Int32")

count = 0
deadline = time.time() + 90
while not resumed.is_set() and time.time() < deadline:
    if client.is_connected:
        talker.publish(roslibpy.Message({"data": count}))
        count += 1
    time.sleep(0.2)
print("resumed after reconnect:", resumed.is_set(), flush=True)
client.terminate()
