"""Leaf helpers: errors, angles, linear algebra, name lookup, seeds, parameter declarations.

Nothing in this package imports anything else of ``replay`` (an import-linter
contract checks it in CI), so every layer above — models, filters, adapters,
tasks, the pipeline, the outputs and the CLI — may use it without cycles.
"""
