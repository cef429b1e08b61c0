"""The runner: the `terrabench` command line, paired flights, tables, charts and reports."""
