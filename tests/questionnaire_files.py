"""The Likert questionnaire file the tests write (the format: participants/questionnaires.py): a
title, instructions, a five-point scale with its ends named, and two items, the second reversed."""

COMFORT = """[questionnaire]
name = "comfort"
title = "Comfort"
instructions = "How much do you agree?"
scale = { min = 1, max = 5, low = "strongly disagree", high = "strongly agree" }
[[questionnaire.items]]
id = "c1"
text = "The ride felt smooth."
[[questionnaire.items]]
id = "c2"
text = "The ride felt jerky."
reversed = true
"""
