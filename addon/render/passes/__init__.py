"""Passes shared by techniques: G-buffer, shadow atlas, accumulation."""
