"""Shared motion and music toolkit."""
