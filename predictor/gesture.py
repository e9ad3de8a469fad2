"""Old path of ``python -m predictor.cli.gesture`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.gesture import main

    print("note: predictor.gesture moved to predictor.cli.gesture (python -m predictor.cli.gesture)", file=sys.stderr)
    sys.exit(main())
