"""PhyAgentOS benchmarks: one script per measurement, one entry point (``python -m bench``).

Each script prints a table and writes ``bench/results/<name>.json``; see ``python -m bench
list`` and the README of each measurement in docs/. The scripts share one harness,
``bench/_harness.py`` (``parser`` with ``--out``, ``write_json``, ``percentile``, ``markdown_table``).
"""
