"""(docstring written in a later commit)"""
