"""Old path of ``python -m fem.cli.finger`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from fem.cli.finger import main

    print("note: fem.finger moved to fem.cli.finger (python -m fem.cli.finger)", file=sys.stderr)
    sys.exit(main())
