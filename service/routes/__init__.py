"""HTTP routes, one module per resource; handlers are named verb_noun."""
