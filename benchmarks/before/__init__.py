"""Verbatim copies of the GM-PHD modules as they were before issue 15's speed work (commit
fea5bab; imports pointed here), the same-run reference of ``bench_gmphd_stonesoup.py``."""
