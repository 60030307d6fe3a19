"""voicectl's common library: message schemas, key expressions, the Zenoh session helper."""
