"""Prints the tables of run.py's JSON (argument: test or loo)."""
import json,sys
r=json.load(open('target/magnetic/results_1.0_2.0_2.0_0.5.json'))
F=['mag','vert','horiz']
def line(k,d,pooled=False):
    o=d['offset']; rs=d['resid_std']
    if pooled: rs={'raw':rs['rraw'],'full':rs['rfull'],'causal_truth':rs['rct'],'causal_blind':rs['rcb']}
    s=f"{k:22s} "+(f"nw={d.get('nwalks','')} ne={d.get('nepochs','')} " if not pooled else '')
    s+="off mean/std/p10/p90 "+" ".join(f"{f[0]}:{o[f]['mean']:+.1f}/{o[f]['std']:.1f}/{o[f]['p10']:+.1f}/{o[f]['p90']:+.1f}" for f in F)
    s+=" | rstd raw/full/ctruth/cblind "+" ".join(f"{f[0]}:{rs['raw'][f]:.1f}/{rs['full'][f]:.1f}/{rs['causal_truth'][f]:.1f}/{rs['causal_blind'][f]:.1f}" for f in F)
    s+=" | sp.std2-8 "+"/".join(f"{d['spatial_std_2_8_med'][f]:.1f}" for f in F)+" |d|3-6 "+"/".join(f"{d['absdiff_3_6_med'][f]:.1f}" for f in F)
    print(s)
def llr(k,d):
    for cnd in ['raw','full','causal_truth','causal_blind']:
        print(f"   LLR {cnd:12s} "+" ; ".join(f"{fs}: "+" ".join(f"{v['mean']:.2f}({v['fpos']:.2f})" for v in d['llr'][f'{cnd}|{fs}'].values()) for fs in ['mag','vert','horiz','v+h']))
which=sys.argv[1] if len(sys.argv)>1 else 'test'
for k,d in r[which].items(): line(k,d)
print('POOLED')
for k,d in r['pooled'].items():
    if k.startswith(which): line(k,d,True); llr(k,d)
