"""Old path of ``python -m predictor.cli.figures`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.figures import main

    print("note: predictor.figures moved to predictor.cli.figures (python -m predictor.cli.figures)", file=sys.stderr)
    sys.exit(main())
