"""trustroute.policies.logic: the scLDTL language.

formula (syntax), spec (spec files), dfa (the automaton), labelling (L(x, b)), trace (logged traces),
lint (warnings), compiled (a spec compiled against a town: DFA, labeller, initial state, step).
"""
