"""Paper p003's algorithms (see ../shared/seeds/README.md and docs/architecture.md)."""
