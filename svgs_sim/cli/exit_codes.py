"""Exit codes of every ``svgs`` command: 0 solved / done, 1 no solution (the reason is printed),
2 bad input or usage, 130 interrupted."""

EXIT_OK, EXIT_NO_SOLUTION, EXIT_BAD_INPUT, EXIT_INTERRUPTED = 0, 1, 2, 130
