"""Payload estimation: recursive least squares per pass and truck accumulation."""
