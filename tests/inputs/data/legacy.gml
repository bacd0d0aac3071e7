<GML spec="0.1b">
<tag>
<header>
<client><name>tagbot test (legacy layout)</name></client>
</header>
<environment>
<screenbounds><x>640</x><y>640</y><z>1</z></screenbounds>
</environment>
<Drawing>
<STROKE>
<Pt><X>0.2</X><Y>0.2</Y><time>0.000000</time></Pt>
<Pt><X>0.4</X><Y>0.2</Y><time>0.100000</time></Pt>
<Pt><X>0.5</X><Y>0.3</Y><time>0.100000</time></Pt>
<Pt><X>0.6</X><Y>0.5</Y><time>0.200000</time></Pt>
</STROKE>
<stroke isdrawing="false">
<pt><x>0.6</x><y>0.5</y><time>0.3</time></pt>
<pt><x>0.7</x><y>0.7</y><time>0.4</time></pt>
</stroke>
<stroke>
<pt><x>0.7</x><y>0.7</y><time>75.200000</time></pt>
</stroke>
<stroke>
<pt><x>0.1</x><y>0.9</y><time>75.500000</time></pt>
<pt><x>0.2</x><y>0.95</y><time>75.600000</time></pt>
</stroke>
</Drawing>
</tag>
</GML>
