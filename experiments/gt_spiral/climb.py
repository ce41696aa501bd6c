# ruff: noqa: E501, E702, E401, E402, I001, E731, B023
"""Climb rate along the GT and MJX trajectories of the same starts (OUT/gt.npz, OUT/mjx_evaluation_exit_qpos.npy, OUT/segments_evaluation_exit_0.json from segment.py)."""
import sys
import numpy as np, json
r=dict(np.load(sys.argv[1] + '/gt.npz')); m=np.load(sys.argv[1] + '/mjx_evaluation_exit_qpos.npy')[:,:,:3]
s=json.load(open(sys.argv[1] + '/segments_evaluation_exit_0.json'))['segments']['0']
q=r['qpos'][1:,:,:3]; goal=r['goal']; z0=r['qpos'][0,:,2]; rise=goal[:,2]-z0; dt=float(r['dt'])
gf=r['fell']; mf=np.array(s['mjx_fell']); ok=~gf & ~mf
print('spiral L6 up, generalist_noent, damping 2 implicit, 200 starts; robots that fell in neither: %d; rise %.2f m' % (ok.sum(), np.median(rise)))
for t in (2,4,6,8,10,12,14,16,18):
    k=int(t/dt)-1; f=lambda p:(p[k,:,2]-z0)/rise
    print(f't {t:2d} s: median fraction of the rise climbed, MuJoCo {np.median(f(q)[ok]):.2f}, MJX {np.median(f(m)[ok]):.2f}')
def t_reach(p, f):
    fr=(p[:,:,2]-z0)/rise; hit=fr>=f; return np.where(hit.any(0), hit.argmax(0)+1, np.nan)*dt
for f in (0.25,0.5,0.9):
    a,b=t_reach(q,f)[ok],t_reach(m,f)[ok]
    print(f'{f:.2f} of the rise: median time MuJoCo {np.nanmedian(a):.1f} s, MJX {np.nanmedian(b):.1f} s; share that reached it {np.isfinite(a).mean():.2f} / {np.isfinite(b).mean():.2f}')
sp=lambda p: np.linalg.norm(p[int(1/dt)-1,:,:2]-p[0,:,:2],axis=-1)
print('planar distance in the first second (spawn landing): MuJoCo %.2f m, MJX %.2f m' % (np.median(sp(q)), np.median(sp(m))))
