"""What a bearer token must be to guard an HTTP API that serves other than loopback.

On loopback the token is a second lock behind the address; with ``--http-allow-remote`` it is the only
one, and anyone who can reach the port may guess it. So a remote API refuses a token that can be
guessed: shorter than ``MIN_REMOTE_TOKEN_LENGTH`` characters, of fewer than ``MIN_DISTINCT_CHARACTERS``
different characters, or one of ``KNOWN_WEAK_TOKENS``, the values that were ever written down in
cipstack's repository and are therefore public (a placeholder copied into a cluster is the usual
way a well-known secret is born). ``openssl rand -hex 32`` makes a token of 64 characters that passes.
"""

from __future__ import annotations

#: A token of 32 hexadecimal digits carries 128 bits: enough against guessing over the network.
MIN_REMOTE_TOKEN_LENGTH = 32
#: ``"a" * 40`` is long and still guessed first; a random token of 32 characters has far more.
MIN_DISTINCT_CHARACTERS = 8
#: Tokens that were shipped in cipstack's repository (manifests, tests), and the placeholders everyone
#: tries first: public values, whatever their length. ``replace-this-token`` was deploy/'s Secret until
#: the overlays stopped shipping one; the tests now make theirs at run time and add none here.
KNOWN_WEAK_TOKENS = frozenset({
    "replace-this-token",
    "fleet-s3cret",
    "s3cret",
    "t0ken",
    "secret",
    "token",
    "changeme",
})
#: How a user makes a token that passes (said in every refusal).
HOW_TO_MAKE_ONE = "make one with `openssl rand -hex 32`"


def weak_token_reason(token: str) -> str | None:
    """Why ``token`` may not guard an API that serves other than loopback, or None when it may. The
    reason never repeats the token (a refusal is logged, and a short token may still be a real one)."""
    if token in KNOWN_WEAK_TOKENS or token.strip().lower() in KNOWN_WEAK_TOKENS:
        return f"the token is one published in cipstack's repository, which anyone can read: {HOW_TO_MAKE_ONE}"
    if len(token) < MIN_REMOTE_TOKEN_LENGTH:
        return (f"the token has {len(token)} characters, and --http-allow-remote needs at least "
                f"{MIN_REMOTE_TOKEN_LENGTH}: {HOW_TO_MAKE_ONE}")
    distinct = len(set(token))
    if distinct < MIN_DISTINCT_CHARACTERS:
        return (f"the token is made of {distinct} different character{'' if distinct == 1 else 's'}, and "
                f"--http-allow-remote needs at least {MIN_DISTINCT_CHARACTERS}: {HOW_TO_MAKE_ONE}")
    return None


__all__ = ["HOW_TO_MAKE_ONE", "KNOWN_WEAK_TOKENS", "MIN_DISTINCT_CHARACTERS", "MIN_REMOTE_TOKEN_LENGTH",
           "weak_token_reason"]
