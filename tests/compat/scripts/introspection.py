"""The introspection calls, blocking and with callbacks."""
import os
import threading

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()
topic = os.environ["TOPIC"]

print("topic listed:", topic in client.get_topics())
print("topic type:", client.get_topic_type(topic))
print("typed topics:", topic in client.get_topics_for_type("std_msgs/msg/String"))
print("services listed:", "/rosapi/topics" in client.get_services())
print("service type:", client.get_service_type("/rosapi/topics"))
print("node listed:", os.environ["NODE"] in client.get_nodes())

done = threading.Event()


def print_topics(result):
    print("callback topics listed:", topic in result["topics"], flush=True)
    done.set()


client.get_topics(print_topics)
done.wait(30)
client.terminate()
