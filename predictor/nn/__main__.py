"""``python -m predictor.nn``, the old path of ``python -m predictor.cli.nn`` (the training
command moved in issue 61; predictor.nn is now the networks' package): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.nn import main

    print("note: the command predictor.nn moved to predictor.cli.nn (python -m predictor.cli.nn)", file=sys.stderr)
    sys.exit(main())
