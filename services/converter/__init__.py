"""Text to orders: the orders-file model, the parser and the converter service."""
