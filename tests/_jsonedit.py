"""Edit a JSON document in place at a path of keys and list indices (the fuzz tests' mutations)."""


def put(doc, path: list[str], value, remove: bool) -> None:
    """Set ``doc[path[0]][path[1]]...`` to ``value`` (``remove``: delete the key); a path that does not exist
    is left alone (list indices are digit strings)."""
    node = doc
    for k in path[:-1]:
        if isinstance(node, list) and k.isdigit() and int(k) < len(node):
            node = node[int(k)]
        elif isinstance(node, dict) and k in node:
            node = node[k]
        else:
            return
    last = path[-1]
    if isinstance(node, list) and last.isdigit() and int(last) < len(node):
        node[int(last)] = value
    elif isinstance(node, dict):
        if remove:
            node.pop(last, None)
        else:
            node[last] = value
