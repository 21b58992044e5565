"""Accuracy of ``--offset auto`` on the shared recordings and on clips cut from them.

Usage: ``.venv/bin/python benchmarks/bench_sync.py [--videos ../shared/data/videos] [--work sync_work]``
(prints two Markdown tables; see ``sena_warp/evaluation/sync_bench.py``).
"""

from __future__ import annotations

from sena_warp.evaluation.sync_bench import main

if __name__ == "__main__":
    main()
