"""Old path of ``python -m predictor.cli.calibrate`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.calibrate import main

    print("note: predictor.calibrate moved to predictor.cli.calibrate (python -m predictor.cli.calibrate)", file=sys.stderr)
    sys.exit(main())
