"""The planning baseline: run.py plans a split's instructions with the semantic parser
(interpret.py) or an OpenAI-compatible endpoint (llm.py). Standard library only."""
