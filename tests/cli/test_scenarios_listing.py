"""`simsat scenarios`: every built-in listed, in aligned columns whatever the length of its name."""
from simsat.scenario import builtin_scenarios
from simsat_cli import main


def test_every_builtin_is_listed_in_aligned_columns(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out.splitlines()
    names = list(builtin_scenarios())
    rows = [ln for ln in out if ln.split(" ", 1)[0] in names]
    assert [r.split(" ", 1)[0] for r in rows] == names
    starts = {r.index(r.split()[1], len(r.split()[0])) for r in rows}
    assert len(starts) == 1  # the size column starts at the same place on every row
