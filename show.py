import sys, json
for f in sys.argv[1:]:
  for l in open(f):
    d=json.loads(l); a=d.pop('args'); print({k:v for k,v in a.items() if k in ('run','post','feat','ctx','ctx_all','loss','beta','epochs','ens','hidden','noise','wd','layers')}, d)
