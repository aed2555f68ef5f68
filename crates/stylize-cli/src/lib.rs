//! Library side of the `stylize` command line: configuration, the loop, run directories.
