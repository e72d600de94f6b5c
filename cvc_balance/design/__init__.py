"""Design for balance (placeholder)."""
