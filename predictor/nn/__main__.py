"""``python -m predictor.nn``, the old path of ``python -m predictor.cli.nn`` (the training
command moved in issue 61; predictor.nn is now the networks' package): runs it. Not for import.

The command is run (runpy), not imported: a package below predictor.cli names nothing of it,
as apps run fem's studies without importing them."""

if __name__ == "__main__":
    import runpy
    import sys

    print("note: the command predictor.nn moved to predictor.cli.nn (python -m predictor.cli.nn)", file=sys.stderr)
    runpy.run_module("predictor.cli.nn", run_name="__main__", alter_sys=True)
