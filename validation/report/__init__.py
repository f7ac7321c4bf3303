"""Reports: tables and figures rendered from stored results through templates."""
