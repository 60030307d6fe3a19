"""The `voicectl` command: runs services, the whole local stack, and typed commands."""
