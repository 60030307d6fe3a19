"""voicectl's services; each one runs as its own process and talks to the others over Zenoh only."""
