"""Paper p001's algorithms (see ../shared/seeds/README.md and docs/architecture.md)."""
