"""Paper p002's algorithms (see ../shared/seeds/README.md and docs/architecture.md)."""
