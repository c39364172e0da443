"""The event-driven style: on_ready, an introspection callback, call_later(terminate), run_forever."""
import os

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))


def show_topics(result):
    print("topics via callback:", "/rosout" in result["topics"], flush=True)
    client.call_later(0.2, client.terminate)


client.on_ready(lambda: client.get_topics(show_topics))
client.run_forever()
print("run_forever returned", flush=True)
