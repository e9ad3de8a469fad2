"""Old path of ``python -m predictor.validation.grasps`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.validation.grasps import main

    print("note: predictor.validate_grasps moved to predictor.validation.grasps (python -m predictor.validation.grasps)", file=sys.stderr)
    sys.exit(main())
