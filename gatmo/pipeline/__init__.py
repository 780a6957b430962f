"""Composition of gatmo's parts over files: localize, run, compare, demo, map build."""
