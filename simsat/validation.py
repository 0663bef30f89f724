"""One validation pass over a whole scenario, into which each stage registers the check of its table.

``load_scenario`` checks the tables simsat itself reads (scene, platform,
attitude, instrument, acquisition, report) and then runs every check
registered here, so that ``simsat validate`` — and every command before it
renders anything — refuses a bad key of *any* stage, naming it. A later stage
(``restore``: ``[restoration]``) registers its check when it is imported; the
command line imports every stage, so its pass is complete.
"""
from __future__ import annotations

from typing import Callable

__all__ = ["register_table_check", "run_table_checks", "TABLE_CHECKS"]

#: table name → check(section) raising simsat.config.ScenarioError naming the key
TABLE_CHECKS: dict[str, Callable] = {}


def register_table_check(table: str, check: Callable) -> None:
    """Register ``check(section)`` for the scenario's ``[table]`` (replacing an earlier one)."""
    TABLE_CHECKS[table] = check


def run_table_checks(scenario) -> list[str]:
    """Run every registered check on its table of ``scenario``; returns the tables checked."""
    for table, check in TABLE_CHECKS.items():
        check(scenario.section(table))
    return list(TABLE_CHECKS)
