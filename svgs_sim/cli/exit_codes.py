"""Exit codes of every ``svgs`` command, documented together (docs/cli.md, README):

====  =====================================================================================
0     done / solved
1     no solution, or a simulated physical failure (the reason is printed)
2     bad input or usage (one line naming the input; nothing was done)
3     output could not be written: a full disk, a path the system refuses, a closed stdout
      or a broken pipe (``io_error``; the files written before are kept and named)
130   interrupted (SIGINT; 143 for SIGTERM)
====  =====================================================================================
"""

EXIT_OK, EXIT_NO_SOLUTION, EXIT_BAD_INPUT, EXIT_IO_ERROR, EXIT_INTERRUPTED = 0, 1, 2, 3, 130
