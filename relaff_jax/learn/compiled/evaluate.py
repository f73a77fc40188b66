"""placeholder"""
votes = proba = None
