"""The sensor log: Parquet streams and their schema, CSV exchange, accuracy metrics."""
