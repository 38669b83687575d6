"""The `vivbench` command line (thin: parse, build the config, call the library)."""


def main(argv=None):  # placeholder until the synth subcommand lands
    raise SystemExit("vivbench: no subcommands yet")
