"""A talker thread with a time.sleep loop and a listener callback, as roslibpy's examples do."""
import os
import threading
import time

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()

heard = []
enough = threading.Event()


def receive_message(message):
    heard.append(message["data"])
    print("Heard talking: " + message["data"], flush=True)
    if len(heard) >= 5:
        enough.set()


listener = roslibpy.Topic(client, os.environ["CHATTER"], "std_msgs/String")
listener.subscribe(receive_message)

talker = roslibpy.Topic(client, os.environ["CHATTER"], "std_msgs/String")


def start_talking():
    count = 0
    while client.is_connected and not enough.is_set():
        talker.publish(roslibpy.Message({"data": f"Hello World {count}"}))
        count += 1
        time.sleep(0.1)
    talker.unadvertise()


thread = threading.Thread(target=start_talking)
thread.start()
enough.wait(60)
thread.join()
listener.unsubscribe()
print("subscribed after unsubscribe:", listener.is_subscribed)
print("in order:", heard == sorted(heard, key=lambda text: int(text.split()[-1])))
client.terminate()
