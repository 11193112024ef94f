"""The application's state and logic that need no Qt: tested without a display."""
