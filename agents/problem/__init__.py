"""The pose-problem file contract (DESIGN.md §3): its schema, images, and solving from a file or an image."""
