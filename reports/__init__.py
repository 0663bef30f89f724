"""What a run and the method look like to a reader: figures, reports and benchmarks (reads truth).

* :mod:`.run_report` — ``simsat report``: the HTML report of a run, from
  :mod:`.report_data` (numbers) and :mod:`.report_plots` (drawing);
* :mod:`.summary` — the terminal summary of a run; :mod:`.metrics` — the
  accuracy metric and misregistration;
* :mod:`.figures` — the founding patent's figures 7–14;
* :mod:`.bench`, :mod:`.bench_matching`, :mod:`.bench_integration` —
  ``simsat bench``; :mod:`.synthetic` — synthetic textures with known shifts;
* :mod:`.keyref` — the scenario key reference (docs/scenario-keys.md);
  :mod:`.plotting` — the house style and atomic figure/table writers.
"""
__all__ = ["run_report", "report_data", "report_plots", "summary", "metrics", "figures", "bench", "bench_matching",
           "bench_integration", "synthetic", "keyref", "plotting"]
