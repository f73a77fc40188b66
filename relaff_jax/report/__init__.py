"""Reports: Table II, findings, figures and the report document."""
