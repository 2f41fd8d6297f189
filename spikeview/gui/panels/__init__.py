"""The five dockable panels of the main window; each is a thin view over the session."""
