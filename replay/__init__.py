"""replay: replay real navigation logs through state-estimation filters and score them."""
__version__ = "0.1.0"
