"""placeholder until the render command lands"""
def add_parser(subparsers):
    p = subparsers.add_parser("render")
    p.set_defaults(func=lambda a: 0)
