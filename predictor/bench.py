"""Old path of ``python -m predictor.validation.bench`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.validation.bench import main

    print("note: predictor.bench moved to predictor.validation.bench (python -m predictor.validation.bench)", file=sys.stderr)
    sys.exit(main())
