"""The plant-wide ledger from the cells' reports (plain data): what died with a restarted cell
run is counted as lost, and the ledger balances."""

from conveyor_twin.plant.ledger import CellReport, ledger_of


def test_ledger_of_a_restarted_cell_counts_what_died_with_it():

    def report(cell, run, **kw):
        m = CellReport(cell=cell, run=run)
        for k, v in kw.items():
            setattr(m, k, v)
        return m
    up = report('a', 1, entered=20.0, in_cell=10.0, exit_link=['ab'], exit_sent=[10],
                exit_accepted=[8], exit_resent=[3])
    old = report('b', 1, in_cell=3.0, left=2.0, entry_link=['ab'], entry_inserted=[5],
                 entry_waiting=[0])
    new = report('b', 2, in_cell=2.0, entry_link=['ab'], entry_inserted=[2],
                 entry_waiting=[1])
    ledger = ledger_of({'a': up, 'b': new}, [old])
    # the old run held 3 at its last report and reported 1 more inserted after it
    assert ledger.lost == 3 + (8 - 5 - 2)
    assert ledger.links['ab'].held == 2 and ledger.links['ab'].waiting == 1
    assert ledger.in_cells == 12 and ledger.left == 2 and ledger.residual == 0.0
    assert ledger_of({'a': up, 'b': new}).lost == 0.0


def test_ledger_of_a_restarted_feeding_cell_counts_what_its_link_dropped():
    # run 1 of `a` had 4 parts in the cell and had sent 10 at its last report; `b` inserted
    # 7 of them (the other 3 were dropped or never came); run 2 sent 5, 2 inserted
    old = CellReport(cell='a', run=1, entered=14.0, in_cell=4.0, exit_link=['ab'],
                       exit_sent=[10], exit_accepted=[6], exit_resent=[0])
    new = CellReport(cell='a', run=2, entered=8.0, in_cell=3.0, exit_link=['ab'],
                       exit_sent=[5], exit_accepted=[2], exit_resent=[0])
    down = CellReport(cell='b', run=1, in_cell=6.0, left=3.0, entry_link=['ab'],
                        entry_inserted=[9], entry_waiting=[0], entry_earlier=[7],
                        entry_dropped=[2])
    ledger = ledger_of({'a': new, 'b': down}, [old])
    assert ledger.lost == 4 + (10 - 7)
    assert ledger.in_links == 3 and ledger.residual == 0.0
    # run 1 sent more after its last report than it held then: parts entered unreported
    down.entry_earlier = [15]
    down.entry_inserted = [17]
    down.in_cell = 14.0
    ledger = ledger_of({'a': new, 'b': down}, [old])
    assert ledger.lost == 0 and ledger.cells['a#unreported']['entered'] == 1
    assert ledger.residual == 0.0
