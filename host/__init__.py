"""Host side: camera sources, CLI."""
