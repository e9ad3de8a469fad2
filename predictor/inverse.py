"""Old path of ``python -m predictor.cli.inverse`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.cli.inverse import main

    print("note: predictor.inverse moved to predictor.cli.inverse (python -m predictor.cli.inverse)", file=sys.stderr)
    sys.exit(main())
