"""Road networks from aerial imagery (Grote & Rottensteiner): segments, road parts, subgraphs."""
