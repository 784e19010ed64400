"""Helpers shared by several studies."""
