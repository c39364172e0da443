"""Actions: a goal with feedback and its result, then a long goal canceled, as roslibpy writes them."""
import os
import threading

import roslibpy_lite.compat as roslibpy

client = roslibpy.Ros(host="127.0.0.1", port=int(os.environ["ROSBRIDGE_PORT"]))
client.run()

action_client = roslibpy.ActionClient(client, os.environ["ACTION"], "test_msgs/action/Fibonacci")
done = threading.Event()
outcome = {}


def on_result(result):
    outcome["result"] = result
    done.set()


def on_feedback(feedback):
    print("Feedback:", list(feedback["sequence"]), flush=True)


def on_error(error):
    outcome["error"] = error
    done.set()


goal_id = action_client.send_goal(roslibpy.Goal({"order": 5}), on_result, on_feedback, on_error)
action_client.wait_goal(goal_id, timeout=30)
done.wait(30)
result = outcome["result"]
print("Result:", list(result["values"]["sequence"]), result["status"], flush=True)

slow_client = roslibpy.ActionClient(client, os.environ["ACTION"] + "_slow",
                                    "test_msgs/action/Fibonacci")
first_feedback = threading.Event()
canceled = threading.Event()


def on_end_slow(result):
    # rosbridge ends a canceled goal with result true: the result callback hears of it
    print("Goal ended:", result["status"], flush=True)
    canceled.set()


slow_id = slow_client.send_goal(roslibpy.Goal({"order": 1}), on_end_slow,
                                lambda feedback: first_feedback.set(), on_end_slow)
first_feedback.wait(30)
slow_client.cancel_goal(slow_id)
print("Canceled in time:", canceled.wait(30), flush=True)

client.terminate()
