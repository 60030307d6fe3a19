"""The browser panel and its HTTP API (Starlette + uvicorn)."""
