"""The front end: line type and frame algebra, voting space, winners, uncertainty, LineExtractor."""
