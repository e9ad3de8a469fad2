"""Old path of ``python -m fem.cli.solve`` (moved in issue 61): runs it. Not for import."""

if __name__ == "__main__":
    import sys

    from fem.cli.solve import main

    print("note: fem.solve moved to fem.cli.solve (python -m fem.cli.solve)", file=sys.stderr)
    sys.exit(main())
