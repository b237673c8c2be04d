"""``python -m cfcontact`` and the ``cfcontact`` command: the command line (see :mod:`cfcontact.cli`).

The command line is imported here, inside the interrupt handling, so that a Ctrl-C while the
libraries load prints one line and exits with 130 (no traceback)."""

import sys


def main() -> int:
    try:
        from cfcontact.cli import main as cli_main
    except KeyboardInterrupt:
        print("cfcontact: interrupted", file=sys.stderr, flush=True)
        return 130
    return cli_main()


if __name__ == "__main__":
    sys.exit(main())
