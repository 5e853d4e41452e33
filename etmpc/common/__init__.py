"""What every floor of etmpc uses: the errors the command line reports as one line
(:mod:`~etmpc.common.errors`), files checked before a run and written atomically
(:mod:`~etmpc.common.outputs`), where the model files and stored test sets live
(:mod:`~etmpc.common.resources`), and sums that decide computed the same way on every machine
(:mod:`~etmpc.common.numerics`).

The ground floor: this package may import no other part of etmpc.
"""
