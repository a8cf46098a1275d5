"""PhyAgentOS benchmarks: one script per measurement, one entry point (``python -m bench``).

Each script prints a table and writes ``bench/results/<name>.json``; see ``python -m bench
list`` and the README of each measurement in docs/.
"""
