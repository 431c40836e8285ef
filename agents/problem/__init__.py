"""The pose-problem file contract (docs/design.md §3): its schema, images, and solving from a file or an image."""
