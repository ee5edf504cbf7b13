"""Report stage: renders stored results as HTML and PDF laid out like the source paper; audits them."""
