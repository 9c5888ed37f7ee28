#!/usr/bin/env python3
"""Free flight from the screen's time against the full run at other shots than the calibration
shot (README.md, "The free-flight bias at other shots").

    python3 shots.py RUNS_DIR

RUNS_DIR holds <shot>/<run>/summary.json, one `hvi-study run` each (jobs.sh in the README).
Writes RUNS_DIR/runs.csv (every run) and prints each free-flight run's differences from the
full run of its shot, point and seed, in per cent."""
import glob, json, os, csv, sys
here=os.path.abspath(sys.argv[1]) if len(sys.argv)>1 else "."
rows=[]
for f in sorted(glob.glob(here+'/*/*/summary.json')):
    s=json.load(open(f)); sc=s['scene']; c=s.get('cloud') or {}
    ff=sc['run'].get('free_flight_after_s')
    rows.append(dict(shot=f.split('/')[-3], particles=s['particles'], v0_m_s=sc['scene']['v0_m_s'], t_over_d=sc['scene']['t_over_d'],
        end_time_s=sc['run']['end_time_s'], eps_j=sc['material']['eps_j'], kappa_n_m=sc['material']['kappa_n_m'], seed=sc['run']['seed'],
        free_flight_after_s=ff if ff is not None else '', steps=s['steps'], wall_seconds_1_thread=round(s['wall_seconds'],1),
        length_ratio=c.get('length_ratio'), front_velocity_ratio=c.get('front_velocity_ratio'), fragmentation=c.get('fragmentation'),
        largest_fragment_mass_fraction=c.get('largest_fragment_mass_fraction'), mean_fragment_diameter_m=c.get('mean_fragment_diameter_m')))
out=os.path.join(here,'runs.csv')
with open(out,'w',newline='') as fh:
    w=csv.DictWriter(fh, fieldnames=list(rows[0].keys())); w.writeheader(); w.writerows(rows)
full={(r['shot'],r['eps_j'],r['kappa_n_m'],r['seed']):r for r in rows if r['free_flight_after_s']==''}
obs=['length_ratio','front_velocity_ratio','fragmentation','largest_fragment_mass_fraction','mean_fragment_diameter_m']
print('shot seed eps kappa ff_us steps(full) R(full) va(full) dR% dva% dF% dlargest% dmean%')
for r in rows:
    if r['free_flight_after_s']=='': continue
    b=full.get((r['shot'],r['eps_j'],r['kappa_n_m'],r['seed']))
    if not b: continue
    d=[100*(float(r[o])/float(b[o])-1) if b[o] else float('nan') for o in obs]
    print(r['shot'], r['seed'], r['eps_j'], '%.3g'%r['kappa_n_m'], '%.2f'%(r['free_flight_after_s']*1e6), '%d(%d)'%(r['steps'],b['steps']), '%.3f %.3f'%(b['length_ratio'],b['front_velocity_ratio']), ' '.join('%+.2f'%x for x in d))
