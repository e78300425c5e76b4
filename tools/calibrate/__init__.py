"""``python -m tools.calibrate``: calibrate the recogniser on a lab's own NAOs (NAO paper 3.1,
3.2.3 eq. 6, 5.2.1, Table 1, Figures 19-20).

Steps (each a module):

- ``plan``: the views to take (distances, orientations, head yaws) and the placements a
  person makes;
- ``capture``: drives an observer NAO-i and a subject NAO-j over qi, prompts where a
  person must place NAO-j, turns NAO-j itself, saves the images and a manifest into a
  capture folder (``folder``), resumable, with a contact sheet;
- ``build``: the orange range (``orange``), the M-base (``masks``) and the D-base
  (``distances``) from a capture folder, written as a calibration folder
  (:mod:`agent.core.perception.calibration`);
- ``check``: recall, precision and distance error of a calibration on held-out captures;
- ``rehearse``: all of it against virtual NAOs (the simulated world over qi).
"""
