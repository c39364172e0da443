"""Rates a person reads at a glance: averaged over a stated window, history kept (issue 50)."""

from __future__ import annotations

from bridge_server.http.rates import RATE_WINDOW, Window, merge_history


def _ticks() -> list[float]:
    """Reading times about a second apart, jittered as a busy loop's ticks are."""
    jitter = [0.0, 0.35, -0.3, 0.4, -0.35, 0.3, -0.4, 0.25, -0.2, 0.35, -0.3, 0.4]
    return [100.0 + i + j for i, j in enumerate(jitter * 3)]


def test_a_steady_10_hz_topic_reads_steady() -> None:
    """A 10 Hz counter read at jittered ticks reads 10 msg/s within 10 %, never 5 or 15."""
    window = Window()
    seen = []
    for t in _ticks():
        window.add(t, {"/steady": (float(int(t * 10)),)})  # 10 messages a second
        rates = window.rates()
        if t - 100.0 >= RATE_WINDOW + 1:
            seen.append(rates["/steady"][0])
    assert seen and all(9.0 <= r <= 11.0 for r in seen), seen


def test_history_of_workers_adds_up_from_the_newest_point() -> None:
    """Two workers' histories merge point by point from the newest: to clients added, from ROS the largest."""
    a = {"window_s": 300, "t": [1.0, 2.0, 3.0], "to_clients_per_s": [1, 2, 3],
         "from_clients_per_s": [0, 0, 1], "from_ros_per_s": [5, 5, 5]}
    b = {"window_s": 300, "t": [2.1, 3.1], "to_clients_per_s": [10, 20],
         "from_clients_per_s": [1, 1], "from_ros_per_s": [4, 6]}
    merged = merge_history([a, b])
    assert merged == {"window_s": 300, "t": [2.0, 3.0], "to_clients_per_s": [12, 23],
                      "from_clients_per_s": [1, 2], "from_ros_per_s": [5, 6]}
