"""Services both ways: serve one, call it blocking and with callbacks, call a ROS node's service."""
import os
import threading

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()
name = os.environ["SERVICE"]


def set_speed(request, response):
    print("Setting speed to {}".format(request["data"]), flush=True)
    response["success"] = True
    response["message"] = "ludicrous" if request["data"] else "normal"
    return True


server = roslibpy.Service(client, name, "std_srvs/SetBool")
server.advertise(set_speed)

caller = roslibpy.Service(client, name, "std_srvs/SetBool")
result = caller.call(roslibpy.ServiceRequest({"data": True}), timeout=30)
print("Service response:", result["message"], flush=True)

answered = threading.Event()


def on_success(response):
    print("Callback response:", response["message"], flush=True)
    answered.set()


def on_error(error):
    print("Callback error:", error, flush=True)
    answered.set()


caller.call(roslibpy.ServiceRequest({"data": False}), on_success, on_error)
answered.wait(30)

refuser = roslibpy.Service(client, name + "_refuse", "std_srvs/Trigger")
refuser.advertise(lambda request, response: False)
try:
    roslibpy.Service(client, name + "_refuse", "std_srvs/Trigger").call(roslibpy.ServiceRequest(), timeout=30)
except roslibpy.core.ServiceException:
    print("Refused call raised ServiceException", flush=True)

failed = threading.Event()
roslibpy.Service(client, name + "_refuse", "std_srvs/Trigger").call(
    roslibpy.ServiceRequest(), lambda response: print("unexpected", response), lambda error: failed.set())
print("Errback called:", failed.wait(30), flush=True)

node_service = roslibpy.Service(client, os.environ["NODE_SERVICE"], "std_srvs/SetBool")
reply = node_service.call(roslibpy.ServiceRequest({"data": True}), timeout=30)
print("ROS node answered:", reply["message"], flush=True)

server.unadvertise()
refuser.unadvertise()
client.terminate()
