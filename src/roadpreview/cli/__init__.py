"""Command-line interface: ``roadpreview <command>``; one module per command."""
