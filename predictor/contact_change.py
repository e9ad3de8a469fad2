"""Old path of ``python -m predictor.validation.contact_change`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from predictor.validation.contact_change import main

    print("note: predictor.contact_change moved to predictor.validation.contact_change (python -m predictor.validation.contact_change)", file=sys.stderr)
    sys.exit(main())
