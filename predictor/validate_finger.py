"""Old path of ``python -m predictor.validation.finger`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.validation.finger import main

    print("note: predictor.validate_finger moved to predictor.validation.finger (python -m predictor.validation.finger)", file=sys.stderr)
    sys.exit(main())
