"""Old path of ``python -m predictor.cli.atlas`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.atlas import main

    print("note: predictor.atlas moved to predictor.cli.atlas (python -m predictor.cli.atlas)", file=sys.stderr)
    sys.exit(main())
