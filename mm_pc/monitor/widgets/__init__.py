"""The monitor's Qt widgets: they draw and forward user intent only."""
