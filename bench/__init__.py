"""End-to-end benchmarks of the bridge (``python -m bench``); see ``bench/run.py``."""
